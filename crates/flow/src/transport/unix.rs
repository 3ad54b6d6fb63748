//! Unix domain socket transport.

use std::io;
use std::path::Path;

use tokio::net::UnixStream;
use tokio::net::unix::{OwnedReadHalf, OwnedWriteHalf};

use super::stream::{StreamReader, StreamWriter};
use super::traits::Transport;

/// A Unix-socket connection carrying FlowProtocol frames.
#[derive(Debug)]
pub struct UnixTransport {
    stream: UnixStream,
    peer: String,
}

impl UnixTransport {
    pub async fn connect(path: &Path) -> io::Result<Self> {
        let stream = UnixStream::connect(path).await?;
        Ok(UnixTransport {
            stream,
            peer: format!("unix:{}", path.display()),
        })
    }

    pub fn from_stream(stream: UnixStream, peer: String) -> Self {
        UnixTransport { stream, peer }
    }
}

impl Transport for UnixTransport {
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
