//! In-process transport: a bounded pipe of shared chunks, so that modules inside the server use exactly the same
//! protocol and SDK as satellites without a payload being copied into the pipe on its way.
//!
//! The writer hands over the chunks a flush is made of (frame headers and payloads, reference-counted `Bytes`) as
//! they are, all of a flush as one batch, so the reader is woken once per flush as by a socket. The reader copies
//! headers into its read buffer, as a socket read would, and gives a payload chunk to the frame reader as it is
//! (`take_exact`), so a large payload crosses without a copy. A byte pipe (`tokio::io::duplex`) copied every
//! payload twice: into the pipe and out of it.

use std::collections::VecDeque;
use std::io;
use std::sync::Arc;

use bytes::{Buf, Bytes, BytesMut};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};

use super::traits::{Transport, TransportRead, TransportWrite};

/// Bytes in flight in each direction before the writer waits (back-pressure). A chunk larger than this counts as
/// this much, so a single large frame still passes.
const PIPE_BYTES: usize = 4 * 1024 * 1024;

/// Read size hint when the read buffer is full, as the socket transports use.
const READ_CHUNK: usize = 64 * 1024;

/// The chunks of one flush in flight, and their share of the pipe's byte budget, given back once the reader has
/// taken all of them.
type Batch = (VecDeque<Bytes>, OwnedSemaphorePermit);

/// One end of an in-process pipe.
#[derive(Debug)]
pub struct MemoryTransport {
    reader: MemoryReader,
    writer: MemoryWriter,
    peer: String,
}

/// Two connected ends: give one to the hub, keep the other.
pub fn pair(name: &str) -> (MemoryTransport, MemoryTransport) {
    let (a_reader, b_writer) = pipe();
    let (b_reader, a_writer) = pipe();
    (
        MemoryTransport {
            reader: a_reader,
            writer: a_writer,
            peer: format!("module:{name}"),
        },
        MemoryTransport {
            reader: b_reader,
            writer: b_writer,
            peer: "hub".into(),
        },
    )
}

/// One direction: the reading end and the writing end.
fn pipe() -> (MemoryReader, MemoryWriter) {
    // Unbounded in chunks, bounded in bytes by the budget: the writer takes its share before it sends.
    let (tx, rx) = mpsc::unbounded_channel();
    let budget = Arc::new(Semaphore::new(PIPE_BYTES));
    (
        MemoryReader {
            rx,
            batch: None,
            budget: budget.clone(),
        },
        MemoryWriter {
            tx: Some(tx),
            budget,
        },
    )
}

impl Transport for MemoryTransport {
    type Reader = MemoryReader;
    type Writer = MemoryWriter;

    fn peer(&self) -> String {
        self.peer.clone()
    }

    fn split(self) -> (MemoryReader, MemoryWriter) {
        (self.reader, self.writer)
    }
}

/// Reading half of an in-process pipe.
#[derive(Debug)]
pub struct MemoryReader {
    rx: mpsc::UnboundedReceiver<Batch>,
    /// What is left of the batch being read (its first chunk possibly in part).
    batch: Option<Batch>,
    budget: Arc<Semaphore>,
}

impl Drop for MemoryReader {
    /// Nobody reads any more: a writer waiting for room is told the pipe is broken instead of waiting forever.
    fn drop(&mut self) {
        self.budget.close();
    }
}

impl MemoryReader {
    /// The chunk to read next, taken off the batch being read or, once that is done, the next batch to arrive;
    /// `None` once every writer has gone. Cancel-safe: nothing is taken while it waits.
    async fn next_chunk(&mut self) -> Option<Bytes> {
        loop {
            if let Some((chunks, _)) = &mut self.batch {
                if let Some(chunk) = chunks.pop_front() {
                    return Some(chunk);
                }
                // Done with it: its budget goes back to the writer.
                self.batch = None;
            }
            self.batch = Some(self.rx.recv().await?);
        }
    }

    /// Puts back what is left of a chunk, to be read first.
    fn unread(&mut self, chunk: Bytes) {
        if let Some((chunks, _)) = &mut self.batch {
            chunks.push_front(chunk);
        }
    }
}

impl TransportRead for MemoryReader {
    /// Copies one chunk, or as much of it as the buffer has room for, as a socket read does: the frame reader
    /// reserves room for the rest of a frame it has begun, and growing the buffer past that would move the partial
    /// frame again. A buffer with no room left gets a read chunk's worth. One chunk per read, so that a payload
    /// chunk behind a frame header is left for [`TransportRead::take_exact`] rather than copied.
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        if buf.capacity() == buf.len() {
            buf.reserve(READ_CHUNK);
        }
        // Every writer has gone: the peer closed.
        let Some(mut chunk) = self.next_chunk().await else {
            return Ok(0);
        };
        let room = buf.capacity() - buf.len();
        let take = chunk.len().min(room);
        buf.extend_from_slice(&chunk[..take]);
        chunk.advance(take);
        if !chunk.is_empty() {
            self.unread(chunk);
        }
        Ok(take)
    }

    /// The next chunk itself when it is exactly `len` bytes: the payload the writer handed over, uncopied.
    async fn take_exact(&mut self, len: usize) -> io::Result<Option<Bytes>> {
        let Some(chunk) = self.next_chunk().await else {
            return Ok(None);
        };
        if chunk.len() == len {
            Ok(Some(chunk))
        } else {
            self.unread(chunk);
            Ok(None)
        }
    }
}

/// Writing half of an in-process pipe.
#[derive(Debug)]
pub struct MemoryWriter {
    /// `None` once shut down.
    tx: Option<mpsc::UnboundedSender<Batch>>,
    budget: Arc<Semaphore>,
}

impl MemoryWriter {
    /// Sends the non-empty chunks as one batch once the pipe has room for them.
    async fn send(&mut self, chunks: VecDeque<Bytes>) -> io::Result<()> {
        let bytes: usize = chunks.iter().map(Bytes::len).sum();
        if bytes == 0 {
            return Ok(());
        }
        // A writer that was shut down fails at once rather than after waiting for room.
        let tx = self.tx.as_ref().ok_or(io::ErrorKind::BrokenPipe)?;
        let share = u32::try_from(bytes.min(PIPE_BYTES)).unwrap_or(u32::MAX);
        let permit = self
            .budget
            .clone()
            .acquire_many_owned(share)
            .await
            .map_err(|_| io::Error::from(io::ErrorKind::BrokenPipe))?;
        tx.send((chunks, permit))
            .map_err(|_| io::Error::from(io::ErrorKind::BrokenPipe))
    }
}

impl TransportWrite for MemoryWriter {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        self.send(VecDeque::from([Bytes::copy_from_slice(data)]))
            .await
    }

    /// Hands the chunks over as they are: a shared payload crosses without a copy. The chunks are taken (left
    /// empty) only once the pipe had room for them.
    async fn write_all_chunks(&mut self, chunks: &mut [Bytes]) -> io::Result<()> {
        let batch: VecDeque<Bytes> = chunks.iter().filter(|c| !c.is_empty()).cloned().collect();
        self.send(batch).await?;
        chunks.iter_mut().for_each(|c| *c = Bytes::new());
        Ok(())
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        self.tx = None;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads everything until the writer closes.
    async fn read_to_end(r: &mut MemoryReader, buf: &mut BytesMut) {
        while r.read_into(buf).await.expect("read") > 0 {}
    }

    #[tokio::test]
    async fn chunks_arrive_whole_and_in_order_through_small_reads() {
        let (a, b) = pair("order-test");
        let (_, mut w) = a.split();
        let (mut r, _) = b.split();
        let chunks: Vec<Bytes> = [3000usize, 0, 10, 70_000, 1]
            .iter()
            .enumerate()
            .map(|(i, &n)| Bytes::from(vec![i as u8 + 1; n]))
            .collect();
        let expected: Vec<u8> = chunks.concat();
        let mut pending = chunks.clone();
        w.write_all_chunks(&mut pending).await.expect("write");
        w.write_all(b"tail").await.expect("write");
        w.shutdown().await.expect("shutdown");
        // A buffer of 1000 bytes at a time: every chunk larger than that is split across reads.
        let mut got = Vec::new();
        loop {
            let mut buf = BytesMut::with_capacity(1000);
            if r.read_into(&mut buf).await.expect("read") == 0 {
                break;
            }
            assert!(buf.len() <= 1000, "a read grew the buffer past its room");
            got.extend_from_slice(&buf);
        }
        assert!(got[..expected.len()] == expected[..], "bytes differ");
        assert_eq!(&got[expected.len()..], b"tail");
    }

    #[tokio::test]
    async fn a_shared_payload_is_not_copied_into_the_pipe() {
        let (a, b) = pair("share-test");
        let (_, mut w) = a.split();
        let (mut r, _) = b.split();
        let payload = Bytes::from(vec![9u8; 50_000]);
        w.write_all_chunks(&mut [payload.clone()])
            .await
            .expect("write");
        // The pipe holds the payload itself: the writer's handle is one of two.
        assert!(!payload.is_unique(), "the pipe copied the payload");
        w.shutdown().await.expect("shutdown");
        let mut buf = BytesMut::new();
        read_to_end(&mut r, &mut buf).await;
        assert_eq!(buf.len(), 50_000);
        assert!(
            payload.is_unique(),
            "the reader kept the chunk after copying it"
        );
    }

    #[tokio::test]
    async fn a_writer_waits_for_room_and_goes_on_once_the_reader_reads() {
        let (a, b) = pair("budget-test");
        let (_, mut w) = a.split();
        let (mut r, _) = b.split();
        let writing = tokio::spawn(async move {
            for _ in 0..3 {
                w.write_all_chunks(&mut [Bytes::from(vec![1u8; PIPE_BYTES / 2 + 1])])
                    .await
                    .expect("write");
            }
            w.shutdown().await.expect("shutdown");
        });
        tokio::task::yield_now().await;
        let mut buf = BytesMut::new();
        read_to_end(&mut r, &mut buf).await;
        writing.await.expect("join");
        assert_eq!(buf.len(), 3 * (PIPE_BYTES / 2 + 1));
    }

    #[tokio::test]
    async fn a_writer_is_told_once_the_reader_has_gone() {
        let (a, b) = pair("gone-test");
        let (_, mut w) = a.split();
        drop(b);
        let big = Bytes::from(vec![0u8; PIPE_BYTES]);
        let first = w.write_all_chunks(&mut [big.clone()]).await;
        let second = w.write_all_chunks(&mut [big]).await;
        assert!(
            first.is_err() || second.is_err(),
            "writes to a dropped reader succeeded"
        );
    }
}
