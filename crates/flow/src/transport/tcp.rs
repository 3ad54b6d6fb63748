//! TCP transport.

use std::io;

use tokio::net::TcpStream;
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};

use super::stream::{StreamReader, StreamWriter};
use super::traits::Transport;

/// A TCP connection carrying FlowProtocol frames.
#[derive(Debug)]
pub struct TcpTransport {
    stream: TcpStream,
    peer: String,
}

impl TcpTransport {
    pub async fn connect(hostport: &str) -> io::Result<Self> {
        let stream = TcpStream::connect(hostport).await?;
        Ok(Self::from_stream(stream))
    }

    /// Wraps an accepted or connected stream. Nagle is disabled: frames are
    /// written whole, and small audio frames must not wait for an ACK.
    pub fn from_stream(stream: TcpStream) -> Self {
        // Failing to set the option only costs latency, never correctness.
        let _ = stream.set_nodelay(true);
        let peer = stream
            .peer_addr()
            .map(|a| format!("tcp:{a}"))
            .unwrap_or_else(|_| "tcp:?".into());
        TcpTransport { stream, peer }
    }
}

impl Transport for TcpTransport {
    type Reader = StreamReader<OwnedReadHalf>;
    type Writer = StreamWriter<OwnedWriteHalf>;

    fn peer(&self) -> String {
        self.peer.clone()
    }

    fn split(self) -> (Self::Reader, Self::Writer) {
        let (r, w) = self.stream.into_split();
        (StreamReader(r), StreamWriter(w))
    }
}
