//! In-process transport: a bounded byte pipe, so that modules inside the server
//! use exactly the same protocol and SDK as satellites.

use tokio::io::{DuplexStream, ReadHalf, WriteHalf};

use super::stream::{StreamReader, StreamWriter};
use super::traits::Transport;

/// Bytes buffered in each direction before the writer waits (back-pressure).
const PIPE_BYTES: usize = 4 * 1024 * 1024;

/// One end of an in-process pipe.
#[derive(Debug)]
pub struct MemoryTransport {
    stream: DuplexStream,
    peer: String,
}

/// Two connected ends: give one to the hub, keep the other.
pub fn pair(name: &str) -> (MemoryTransport, MemoryTransport) {
    let (a, b) = tokio::io::duplex(PIPE_BYTES);
    (
        MemoryTransport {
            stream: a,
            peer: format!("module:{name}"),
        },
        MemoryTransport {
            stream: b,
            peer: "hub".into(),
        },
    )
}

impl Transport for MemoryTransport {
    type Reader = StreamReader<ReadHalf<DuplexStream>>;
    type Writer = StreamWriter<WriteHalf<DuplexStream>>;

    fn peer(&self) -> String {
        self.peer.clone()
    }

    fn split(self) -> (Self::Reader, Self::Writer) {
        let (r, w) = tokio::io::split(self.stream);
        (StreamReader(r), StreamWriter(w))
    }
}
