//! Adapters that let any tokio byte stream half act as a transport half.

use std::io::{self, IoSlice};

use bytes::{Buf, Bytes, BytesMut};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use super::traits::{TransportRead, TransportWrite};

/// Read size hint: big enough to take several video frames per system call.
const READ_CHUNK: usize = 64 * 1024;
/// Buffers handed to one vectored write; Linux accepts up to 1024.
const MAX_IOV: usize = 64;

/// Reading half of a byte stream.
#[derive(Debug)]
pub struct StreamReader<R>(pub R);

/// Writing half of a byte stream.
#[derive(Debug)]
pub struct StreamWriter<W>(pub W);

impl<R: AsyncRead + Unpin + Send + 'static> TransportRead for StreamReader<R> {
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        // The frame reader reserves room for the rest of a frame it has begun;
        // reserving more on top would move (copy) that partial frame a second
        // time. Only a buffer with no room left gets a fresh read chunk.
        if buf.capacity() == buf.len() {
            buf.reserve(READ_CHUNK);
        }
        self.0.read_buf(buf).await
    }
}

impl<W: AsyncWrite + Unpin + Send + 'static> TransportWrite for StreamWriter<W> {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        self.0.write_all(data).await
    }

    /// One `writev` per call for up to [`MAX_IOV`] chunks, resuming after a
    /// partial write, so headers and shared payloads leave in one system call
    /// without being copied together first.
    async fn write_all_chunks(&mut self, chunks: &mut [Bytes]) -> io::Result<()> {
        let mut first = 0;
        loop {
            // Empty chunks would make a write of nothing look like a closed peer.
            while chunks.get(first).is_some_and(Bytes::is_empty) {
                first += 1;
            }
            if first == chunks.len() {
                return Ok(());
            }
            let mut slices = [IoSlice::new(&[]); MAX_IOV];
            let mut count = 0;
            for (slot, chunk) in slices.iter_mut().zip(&chunks[first..]) {
                *slot = IoSlice::new(chunk);
                count += 1;
            }
            let mut written = self.0.write_vectored(&slices[..count]).await?;
            if written == 0 {
                return Err(io::ErrorKind::WriteZero.into());
            }
            while written > 0 {
                let Some(chunk) = chunks.get_mut(first) else {
                    break;
                };
                let take = written.min(chunk.len());
                chunk.advance(take);
                written -= take;
                if chunk.is_empty() {
                    first += 1;
                }
            }
        }
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        self.0.shutdown().await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::AsyncReadExt;

    /// A pipe far smaller than the chunks forces partial writes that end in
    /// the middle of a chunk; the bytes still arrive whole and in order.
    #[tokio::test]
    async fn chunks_survive_partial_writes() {
        let (a, mut b) = tokio::io::duplex(777);
        let chunks: Vec<Bytes> = [3000usize, 0, 10, 5000, 1]
            .iter()
            .enumerate()
            .map(|(i, &n)| Bytes::from(vec![i as u8 + 1; n]))
            .collect();
        let expected: Vec<u8> = chunks.concat();
        let reader = tokio::spawn(async move {
            let mut got = Vec::new();
            b.read_to_end(&mut got).await.map(|_| got)
        });
        let mut writer = StreamWriter(a);
        let mut pending = chunks.clone();
        writer.write_all_chunks(&mut pending).await.expect("write");
        writer.shutdown().await.expect("shutdown");
        drop(writer);
        let got = reader.await.expect("join").expect("read");
        assert!(got == expected, "bytes differ after partial writes");
    }
}
