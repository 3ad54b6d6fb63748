//! A payload received from Zenoh as `Bytes`, shared where that is cheap and safe, copied where it is not.

use bytes::Bytes;
use zenoh::bytes::ZBytes;

/// Payloads of at least this many bytes that Zenoh holds in one piece are shared, not copied: a video frame is
/// most of the receive batch it arrived in anyway. A smaller one (20 ms of audio) is copied, so that it does not
/// keep a whole batch of other samples alive while it waits in subscribers' queues.
const SHARE_MIN: usize = 16 * 1024;

/// A received payload that is one contiguous slice, kept alive by its `ZBytes`.
struct Contiguous(ZBytes);

impl AsRef<[u8]> for Contiguous {
    fn as_ref(&self) -> &[u8] {
        // Built only for a payload of exactly one slice (`received`).
        self.0.slices().next().unwrap_or(&[])
    }
}

/// `payload` as `Bytes`: the very buffer Zenoh received when it is large and in one piece, else a copy.
pub(super) fn received(payload: &ZBytes) -> Bytes {
    let mut slices = payload.slices();
    let one_piece =
        matches!((slices.next(), slices.next()), (Some(s), None) if s.len() >= SHARE_MIN);
    if one_piece {
        Bytes::from_owner(Contiguous(payload.clone()))
    } else {
        Bytes::from(payload.to_bytes().into_owned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_large_payload_in_one_piece_is_shared() {
        let data: Vec<u8> = (0..50_000u32).map(|i| i as u8).collect();
        let z = ZBytes::from(data.clone());
        let first = z.slices().next().map(<[u8]>::as_ptr);
        let bytes = received(&z);
        assert_eq!(&bytes[..], &data[..]);
        assert_eq!(Some(bytes.as_ptr()), first, "the payload was copied");
    }

    #[test]
    fn a_small_payload_is_copied() {
        let z = ZBytes::from(vec![7u8; 882]);
        let first = z.slices().next().map(<[u8]>::as_ptr);
        let bytes = received(&z);
        assert_eq!(&bytes[..], &[7u8; 882][..]);
        assert_ne!(Some(bytes.as_ptr()), first);
    }

    #[test]
    fn a_payload_in_pieces_is_joined() {
        let mut writer = ZBytes::writer();
        writer.append(ZBytes::from(vec![1u8; 20_000]));
        writer.append(ZBytes::from(vec![2u8; 20_000]));
        let z = writer.finish();
        let bytes = received(&z);
        assert_eq!(bytes.len(), 40_000);
        assert!(bytes[..20_000].iter().all(|b| *b == 1) && bytes[20_000..].iter().all(|b| *b == 2));
    }
}
