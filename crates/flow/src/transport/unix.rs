//! Unix domain socket transport: a byte stream like TCP, and the one transport that passes descriptors, which the
//! shared-memory path needs (`crate::shm`).

use std::collections::VecDeque;
use std::io;
use std::os::fd::{BorrowedFd, OwnedFd};
use std::path::Path;

use bytes::{Bytes, BytesMut};
use tokio::io::AsyncWriteExt;
use tokio::net::UnixStream;
use tokio::net::unix::{OwnedReadHalf, OwnedWriteHalf};

use super::stream::{StreamReader, StreamWriter};
use super::traits::{Transport, TransportRead, TransportWrite};
use crate::shm::fdpass;

/// A Unix-socket connection carrying FlowProtocol frames.
#[derive(Debug)]
pub struct UnixTransport {
    stream: UnixStream,
    peer: String,
    /// Whether the reading side keeps descriptors that come beside the bytes. A client does (the hub hands it
    /// segments); the hub does not, so that a client cannot make it hold descriptors: the kernel closes them.
    take_fds: bool,
}

impl UnixTransport {
    /// A client's connection: it keeps the descriptors the hub sends.
    pub async fn connect(path: &Path) -> io::Result<Self> {
        let stream = UnixStream::connect(path).await?;
        Ok(UnixTransport {
            stream,
            peer: format!("unix:{}", path.display()),
            take_fds: true,
        })
    }

    /// An accepted connection (the hub's side): descriptors sent to it are dropped unread.
    pub fn from_stream(stream: UnixStream, peer: String) -> Self {
        UnixTransport {
            stream,
            peer,
            take_fds: false,
        }
    }
}

/// Reading half: plain reads, or `recvmsg` keeping the descriptors that came.
#[derive(Debug)]
pub struct UnixReader {
    half: StreamReader<OwnedReadHalf>,
    /// The descriptors received and not taken yet, with the scratch `recvmsg` reads into; `None` on the hub's side.
    fds: Option<(VecDeque<OwnedFd>, Vec<u8>)>,
}

/// Writing half: vectored writes, and `sendmsg` for a frame with a descriptor.
#[derive(Debug)]
pub struct UnixWriter(StreamWriter<OwnedWriteHalf>);

impl Transport for UnixTransport {
    type Reader = UnixReader;
    type Writer = UnixWriter;

    fn peer(&self) -> String {
        self.peer.clone()
    }

    fn passes_fds(&self) -> bool {
        true
    }

    fn split(self) -> (Self::Reader, Self::Writer) {
        let (r, w) = self.stream.into_split();
        let fds = self
            .take_fds
            .then(|| (VecDeque::new(), vec![0; fdpass::READ_CHUNK]));
        (
            UnixReader {
                half: StreamReader(r),
                fds,
            },
            UnixWriter(StreamWriter(w)),
        )
    }
}

impl TransportRead for UnixReader {
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        match &mut self.fds {
            Some((fds, scratch)) => {
                fdpass::recv_with_fds(self.half.0.as_ref(), scratch, buf, fds).await
            }
            None => self.half.read_into(buf).await,
        }
    }

    fn take_fd(&mut self) -> Option<OwnedFd> {
        self.fds.as_mut()?.0.pop_front()
    }
}

impl TransportWrite for UnixWriter {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        self.0.write_all(data).await
    }

    async fn write_all_chunks(&mut self, chunks: &mut [Bytes]) -> io::Result<()> {
        self.0.write_all_chunks(chunks).await
    }

    async fn send_with_fd(&mut self, data: &[u8], fd: BorrowedFd<'_>) -> io::Result<()> {
        let sent = fdpass::send_with_fd(self.0.0.as_ref(), data, fd).await?;
        self.0.0.write_all(&data[sent..]).await
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        self.0.shutdown().await
    }
}
