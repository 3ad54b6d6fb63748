//! Adapters that let any tokio byte stream half act as a transport half.

use std::io;

use bytes::BytesMut;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use super::{TransportRead, TransportWrite};

/// Read size hint: big enough to take several video frames per system call.
const READ_CHUNK: usize = 64 * 1024;

/// Reading half of a byte stream.
#[derive(Debug)]
pub struct StreamReader<R>(pub R);

/// Writing half of a byte stream.
#[derive(Debug)]
pub struct StreamWriter<W>(pub W);

impl<R: AsyncRead + Unpin + Send + 'static> TransportRead for StreamReader<R> {
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        buf.reserve(READ_CHUNK);
        self.0.read_buf(buf).await
    }
}

impl<W: AsyncWrite + Unpin + Send + 'static> TransportWrite for StreamWriter<W> {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        self.0.write_all(data).await
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        self.0.shutdown().await
    }
}
