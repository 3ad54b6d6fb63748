//! The payloads measured: 64 KB and 1 MB of patterned bytes (a large percept, a raw frame), and the 640x360
//! camera JPEG that `Agent.video` carries, read by hub-bench's own loader so that both benches send the same
//! picture.

use std::path::Path;

use crate::hub_payloads;

/// One payload.
#[derive(Debug, Clone)]
pub struct Payload {
    /// The name on the command line and in the SUMMARY lines: `64k`, `1m`, `jpeg`.
    pub name: &'static str,
    pub bytes: Vec<u8>,
}

impl Payload {
    /// How the tables name it, with its size.
    pub fn label(&self) -> String {
        match self.name {
            "jpeg" => format!("jpeg 640x360 ({} B)", self.bytes.len()),
            _ => format!("{} ({} B)", self.human(), self.bytes.len()),
        }
    }

    /// `64 KB`, `1 MB`, or `jpeg`.
    pub fn human(&self) -> &'static str {
        match self.name {
            "64k" => "64 KB",
            "1m" => "1 MB",
            _ => "jpeg",
        }
    }
}

/// `len` bytes that are not all alike (no mode may gain from a page of zeros).
fn patterned(name: &'static str, len: usize) -> Payload {
    let bytes = (0..len).map(|i| (i % 251) as u8).collect();
    Payload { name, bytes }
}

/// Every payload, in the order measured.
pub fn all(fixtures: &Path) -> anyhow::Result<Vec<Payload>> {
    let jpeg = hub_payloads::jpeg(fixtures)?;
    Ok(vec![
        patterned("64k", 64 * 1024),
        patterned("1m", 1024 * 1024),
        Payload {
            name: "jpeg",
            bytes: jpeg.bytes,
        },
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterned_payloads_have_their_size_and_vary() {
        let p = patterned("64k", 64 * 1024);
        assert_eq!(p.bytes.len(), 65536);
        assert_ne!(p.bytes[0], p.bytes[1]);
        assert_eq!(p.label(), "64 KB (65536 B)");
    }
}
