//! One struct per direction owning a transport half and its buffer: frames in,
//! frames out. Framing rules live in [`crate::protocol::frame`]; this is only
//! the loop that feeds bytes to them.

use std::collections::VecDeque;
use std::io;

use bytes::{Bytes, BytesMut};
use thiserror::Error;

use crate::protocol::frame::{self, Check, RawFrame};
use crate::protocol::{FrameError, codec};
use crate::transport::{Transport, TransportRead, TransportWrite};

/// Why reading or writing frames stopped.
#[derive(Debug, Error)]
pub enum ConnError {
    #[error("i/o: {0}")]
    Io(#[from] io::Error),
    #[error("bad frame: {0}")]
    Frame(#[from] FrameError),
    #[error("peer closed the connection in the middle of a frame")]
    TruncatedFrame,
}

/// Room made for reading when a frame needs more than the buffer has: enough
/// for several small frames, or a large part of a video frame, per read.
const READ_RESERVE: usize = 64 * 1024;

/// Bytes of earlier read buffers kept for reuse once the frames cut from them
/// are gone: about 30 camera frames, as many as are typically on their way to
/// subscribers at once when a publisher streams video flat out.
const SPARE_BYTES: usize = 2 * 1024 * 1024;
/// Room beyond the frame being completed when a new read buffer is made, for
/// the frames that follow it in the same read; the start of a frame that does
/// not fit is copied to the next buffer.
const READ_SLACK: usize = 16 * 1024;

/// Reads whole frames from a transport.
///
/// Large frames are views into the read buffer (no copy on the way in), so a
/// buffer stays pinned while its frames wait in queues. Instead of allocating
/// a fresh buffer each time the current one is pinned and full, the reader
/// keeps the pinned ones aside and takes one back once every frame cut from
/// it has been dropped. With the system allocator, a fresh 64 kB+ block per
/// video frame meant the heap was trimmed and grown again for every frame,
/// and each page of it faulted in anew: that cost the hub about a third of
/// its throughput on 52 kB camera frames (docs/bench-hub.md).
#[derive(Debug)]
pub struct FrameReader<R> {
    io: R,
    buf: BytesMut,
    /// Size of `buf`'s allocation (its capacity shrinks as frames are cut off).
    buf_size: usize,
    /// Earlier read buffers with their allocation sizes, oldest first: empty,
    /// possibly still shared with frames in use.
    spare: VecDeque<(BytesMut, usize)>,
    /// Sum of the sizes in `spare`, at most [`SPARE_BYTES`].
    spare_bytes: usize,
    /// Read buffers allocated since the start (a figure for tests and tuning).
    allocated: u64,
    max_frame: usize,
}

/// A frame is a view into the read buffer. A small body would keep that whole buffer (64 kB or more) alive for as
/// long as it waits in subscribers' lanes, so 64 queued 882-byte audio chunks could pin megabytes; it gets its own
/// copy, which costs next to nothing at that size. Large payloads stay views: they are most of their buffer anyway,
/// and fan-out shares them uncopied. A tail is a buffer of its own and stays as it is.
fn own_small_body(mut frame: RawFrame) -> RawFrame {
    if frame.body.len() < ZERO_COPY_MIN {
        frame.body = Bytes::copy_from_slice(&frame.body);
    }
    frame
}

impl<R: TransportRead> FrameReader<R> {
    pub fn new(io: R, max_frame: usize) -> Self {
        FrameReader {
            io,
            buf: BytesMut::with_capacity(READ_RESERVE),
            buf_size: READ_RESERVE,
            spare: VecDeque::new(),
            spare_bytes: 0,
            allocated: 1,
            max_frame,
        }
    }

    /// Changes the largest frame accepted from now on (a hub allows only a small one before login).
    pub fn set_max_frame(&mut self, max_frame: usize) {
        self.max_frame = max_frame;
    }

    /// The oldest descriptor that came beside the bytes read so far (see [`TransportRead::take_fd`]).
    pub fn take_fd(&mut self) -> Option<std::os::fd::OwnedFd> {
        self.io.take_fd()
    }

    /// Bytes of a frame begun but not complete yet (what a peer that stops mid-frame holds).
    pub fn partial(&self) -> usize {
        self.buf.len()
    }

    /// How many read buffers this reader has allocated, the first included.
    pub fn buffers_allocated(&self) -> u64 {
        self.allocated
    }

    /// The next frame, or `None` when the peer closed cleanly between frames.
    pub async fn read_frame(&mut self) -> Result<Option<RawFrame>, ConnError> {
        loop {
            if let Some(frame) = self.parse_buffered()? {
                return Ok(Some(frame));
            }
            // The rest of a begun frame may wait in the transport as one shared buffer (a payload handed over an
            // in-process link): it becomes the frame's tail as it is, instead of being copied in behind the header.
            if let Some(need) = self.rest_of_begun_frame()?
                && let Some(tail) = self.io.take_exact(need).await?
            {
                let frame = frame::parse_with_tail(&mut self.buf, tail);
                return Ok(Some(own_small_body(frame)));
            }
            if self.io.read_into(&mut self.buf).await? == 0 {
                return if self.buf.is_empty() {
                    Ok(None)
                } else {
                    Err(ConnError::TruncatedFrame)
                };
            }
        }
    }

    /// How many bytes the frame begun in the buffer still needs, once its header is all there; `None` otherwise.
    fn rest_of_begun_frame(&self) -> Result<Option<usize>, FrameError> {
        if self.buf.len() < frame::HEADER_LEN {
            return Ok(None);
        }
        Ok(match frame::check(&self.buf, self.max_frame)? {
            Check::Incomplete(total) => Some(total - self.buf.len()),
            Check::Complete(_) => None,
        })
    }

    /// A frame already in the buffer, if any; never waits.
    pub fn parse_buffered(&mut self) -> Result<Option<RawFrame>, FrameError> {
        match frame::check(&self.buf, self.max_frame)? {
            Check::Complete(total) => Ok(Some(own_small_body(frame::parse(&mut self.buf, total)))),
            Check::Incomplete(total) => {
                // Make room only when the rest of the frame does not fit:
                // every move copies the partial frame, and a large one would
                // be copied once per read. The length was checked against the
                // maximum, so the room made is bounded.
                let need = total.saturating_sub(self.buf.len());
                if self.buf.capacity() - self.buf.len() < need {
                    self.make_room(need);
                }
                Ok(None)
            }
        }
    }

    /// Gives `buf` room for `need` more bytes, reusing a buffer whose frames
    /// are all gone where there is one.
    fn make_room(&mut self, need: usize) {
        let held = self.buf.len();
        // Nothing cut from the current buffer is alive any more: it can take
        // the rest of the frame where it is (moving the partial frame to its
        // front at most).
        if self.buf.try_reclaim(need) {
            return;
        }
        let wanted = held + need;
        // A failed `try_reclaim` leaves a buffer as it was; a successful one
        // makes the whole allocation available again.
        let reused = self
            .spare
            .iter_mut()
            .position(|(b, _)| b.try_reclaim(wanted));
        let (mut next, next_size) = match reused.and_then(|i| self.spare.remove(i)) {
            Some((b, size)) => {
                self.spare_bytes -= size;
                (b, size)
            }
            None => {
                self.allocated += 1;
                let size = grown_capacity(wanted);
                (BytesMut::with_capacity(size), size)
            }
        };
        next.extend_from_slice(&self.buf);
        let mut old = std::mem::replace(&mut self.buf, next);
        let old_size = std::mem::replace(&mut self.buf_size, next_size);
        old.clear();
        // The oldest spares are the most likely to be free already; one that
        // frames still pin after this many others is held by a slow consumer,
        // so those frames may own it alone.
        while self.spare_bytes + old_size > SPARE_BYTES {
            let Some((_, size)) = self.spare.pop_front() else {
                break;
            };
            self.spare_bytes -= size;
        }
        if old_size <= SPARE_BYTES {
            self.spare_bytes += old_size;
            self.spare.push_back((old, old_size));
        }
    }
}

/// Capacity of a new read buffer that must hold `wanted` bytes now: that
/// and a little more, so the next frame's first bytes fit behind it, and at
/// least the usual read size. Not more: a buffer lives as long as any frame
/// cut from it, so one that held several video frames would stay pinned by
/// whichever of them a subscriber still queues, multiplying the memory that
/// queued frames really need.
fn grown_capacity(wanted: usize) -> usize {
    wanted.saturating_add(READ_SLACK).max(READ_RESERVE)
}

/// Payloads at least this large are sent from their own shared buffer
/// (vectored write) instead of being copied next to their header; smaller
/// ones are cheaper to copy than to track as a separate piece.
pub const ZERO_COPY_MIN: usize = 4 * 1024;

/// Encodes frames and writes them out in batches.
///
/// Small frames and the headers of large ones are encoded into one growing
/// buffer; large payloads join the batch as shared [`Bytes`] chunks, so the
/// hub fans a video frame out to N connections without N copies of it.
#[derive(Debug)]
pub struct FrameWriter<W> {
    io: W,
    buf: BytesMut,
    /// Finished pieces of the batch, in order; `buf` follows them.
    chunks: Vec<Bytes>,
    chunk_bytes: usize,
}

impl<W: TransportWrite> FrameWriter<W> {
    pub fn new(io: W) -> Self {
        FrameWriter {
            io,
            buf: BytesMut::with_capacity(64 * 1024),
            chunks: Vec::new(),
            chunk_bytes: 0,
        }
    }

    /// The pending output buffer, for encoders to append frames to.
    pub fn buffer(&mut self) -> &mut BytesMut {
        &mut self.buf
    }

    pub fn queue_event(&mut self, event: &crate::protocol::Event) {
        match event {
            crate::protocol::Event::Data {
                chan,
                seq,
                ts_us,
                payload,
            } if payload.len() >= ZERO_COPY_MIN => {
                codec::encode_data_head(*chan, *seq, *ts_us, payload.len(), &mut self.buf);
                self.push_chunk(payload.clone());
            }
            other => codec::encode_event(other, &mut self.buf),
        }
    }

    pub fn queue_command(&mut self, env: &crate::protocol::Envelope) {
        codec::encode_command(env, &mut self.buf);
    }

    /// Queues already encoded frames, sharing rather than copying large ones.
    pub fn queue_encoded(&mut self, frames: Bytes) {
        if frames.len() >= ZERO_COPY_MIN {
            self.push_chunk(frames);
        } else {
            self.buf.extend_from_slice(&frames);
        }
    }

    /// Appends `chunk` after everything queued so far.
    fn push_chunk(&mut self, chunk: Bytes) {
        if !self.buf.is_empty() {
            let head = self.buf.split().freeze();
            self.chunk_bytes += head.len();
            self.chunks.push(head);
        }
        self.chunk_bytes += chunk.len();
        self.chunks.push(chunk);
    }

    /// Bytes waiting to be written.
    pub fn pending(&self) -> usize {
        self.chunk_bytes + self.buf.len()
    }

    /// Writes everything queued, then `event` with `fd` beside it (a shared-memory segment's descriptor; Unix
    /// socket only).
    pub async fn send_event_with_fd(
        &mut self,
        event: &crate::protocol::Event,
        fd: std::os::fd::BorrowedFd<'_>,
    ) -> io::Result<()> {
        self.flush().await?;
        let mut frame = BytesMut::new();
        codec::encode_event(event, &mut frame);
        self.io.send_with_fd(&frame, fd).await
    }

    /// Writes everything queued.
    pub async fn flush(&mut self) -> io::Result<()> {
        if self.chunks.is_empty() {
            if !self.buf.is_empty() {
                self.io.write_all(&self.buf).await?;
                self.buf.clear();
            }
            return Ok(());
        }
        if !self.buf.is_empty() {
            self.chunks.push(self.buf.split().freeze());
        }
        let result = self.io.write_all_chunks(&mut self.chunks).await;
        // Dropping the written pieces lets `buf` reuse its allocation.
        self.chunks.clear();
        self.chunk_bytes = 0;
        result
    }

    pub async fn shutdown(&mut self) -> io::Result<()> {
        self.flush().await?;
        self.io.shutdown().await
    }
}

/// A transport with its framing state in both directions.
#[derive(Debug)]
pub struct Connection<T: Transport> {
    pub peer: String,
    pub reader: FrameReader<T::Reader>,
    pub writer: FrameWriter<T::Writer>,
}

impl<T: Transport> Connection<T> {
    pub fn new(transport: T, max_frame: usize) -> Self {
        let peer = transport.peer();
        let (r, w) = transport.split();
        Connection {
            peer,
            reader: FrameReader::new(r, max_frame),
            writer: FrameWriter::new(w),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::Event;
    use crate::transport::Transport;
    use crate::transport::memory;
    use crate::transport::stream::{StreamReader, StreamWriter};
    use tokio::io::DuplexStream;

    /// A byte stream, as a socket is: the writer's end and the reader's.
    fn byte_pipe() -> (StreamWriter<DuplexStream>, StreamReader<DuplexStream>) {
        let (a, b) = tokio::io::duplex(4 * 1024 * 1024);
        (StreamWriter(a), StreamReader(b))
    }

    /// A small frame owns its bytes, so it does not keep the read buffer alive;
    /// a large one is a view into that buffer.
    #[tokio::test]
    async fn small_frames_do_not_pin_the_read_buffer() {
        let (w, r) = byte_pipe();
        let mut writer = FrameWriter::new(w);
        for len in [882usize, 100_000] {
            writer.queue_event(&Event::Data {
                chan: 1,
                seq: 1,
                ts_us: 0,
                payload: Bytes::from(vec![7u8; len]),
            });
        }
        writer.flush().await.expect("flush");
        let mut reader = FrameReader::new(r, 1 << 20);
        let small = reader.read_frame().await.expect("read").expect("frame");
        let large = reader.read_frame().await.expect("read").expect("frame");
        assert!(
            small.body.is_unique(),
            "a small frame shares the read buffer"
        );
        assert!(!large.body.is_unique(), "a large frame was copied");
    }

    /// Video-sized frames read one after another reuse the read buffers their
    /// predecessors were cut from once those are dropped; frames that are
    /// kept pin their buffers, and the reader allocates new ones instead.
    #[tokio::test]
    async fn read_buffers_are_reused_once_their_frames_are_gone() {
        async fn read_all(keep: bool) -> u64 {
            let (w, r) = byte_pipe();
            let mut writer = FrameWriter::new(w);
            let mut reader = FrameReader::new(r, 1 << 20);
            let mut kept = Vec::new();
            for seq in 0..60u64 {
                writer.queue_event(&Event::Data {
                    chan: 1,
                    seq,
                    ts_us: 0,
                    payload: Bytes::from(vec![seq as u8; 52_000]),
                });
                writer.flush().await.expect("flush");
                let frame = reader.read_frame().await.expect("read").expect("frame");
                let event = crate::protocol::decode_event(frame).expect("decode");
                let Event::Data { payload, .. } = event else {
                    panic!("not data: {event:?}");
                };
                assert!(
                    payload.iter().all(|b| *b == seq as u8),
                    "frame {seq} damaged"
                );
                if keep {
                    kept.push(payload);
                }
            }
            reader.buffers_allocated()
        }
        let reused = read_all(false).await;
        let pinned = read_all(true).await;
        assert!(reused <= 3, "{reused} buffers for frames dropped at once");
        assert!(
            pinned >= 10,
            "only {pinned} buffers for 60 kept 52 kB frames"
        );
    }

    /// Over an in-process link a large payload arrives as the frame's tail, the very buffer the writer queued, and
    /// decodes to it; a small one is copied with its header as over a socket.
    #[tokio::test]
    async fn an_in_process_link_hands_a_large_payload_over_uncopied() {
        let (a, b) = memory::pair("tail-test");
        let (_, w) = a.split();
        let (r, _) = b.split();
        let mut writer = FrameWriter::new(w);
        let large = Bytes::from(vec![5u8; 100_000]);
        for (seq, payload) in [
            (1, Bytes::from(vec![7u8; 882])),
            (2, large.clone()),
            (3, Bytes::from_static(b"end")),
        ] {
            writer.queue_event(&Event::Data {
                chan: 1,
                seq,
                ts_us: 0,
                payload,
            });
        }
        writer.flush().await.expect("flush");
        let mut reader = FrameReader::new(r, 1 << 20);
        let mut got = Vec::new();
        for _ in 0..3 {
            let frame = reader.read_frame().await.expect("read").expect("frame");
            let tail = frame.tail.len();
            let Event::Data { seq, payload, .. } =
                crate::protocol::decode_event(frame).expect("decode")
            else {
                panic!("not data");
            };
            got.push((seq, tail, payload));
        }
        assert_eq!((got[0].0, got[0].1, got[0].2.len()), (1, 0, 882));
        assert_eq!((got[1].0, got[1].1), (2, 100_000));
        assert_eq!(
            got[1].2.as_ptr(),
            large.as_ptr(),
            "the large payload was copied"
        );
        assert_eq!((got[2].0, got[2].1, &got[2].2[..]), (3, 0, &b"end"[..]));
    }

    /// Small and large payloads, mixed with other events, arrive byte-identical
    /// to the plain encoding whether they were copied or sent as shared chunks.
    #[tokio::test]
    async fn shared_payload_chunks_match_the_plain_encoding() {
        let (a, b) = memory::pair("writer-test");
        let (_, w) = a.split();
        let (mut r, _) = b.split();
        let mut writer = FrameWriter::new(w);
        let events: Vec<Event> = [10usize, ZERO_COPY_MIN, 3, 100_000, 0]
            .iter()
            .enumerate()
            .flat_map(|(i, &len)| {
                let payload = Bytes::from((0..len).map(|b| (b * 7 + i) as u8).collect::<Vec<_>>());
                [
                    Event::Data {
                        chan: i as i16,
                        seq: i as u64 + 1,
                        ts_us: 1000 + i as u64,
                        payload,
                    },
                    Event::StartPublishing { id: i as i16 },
                ]
            })
            .collect();
        let mut plain = BytesMut::new();
        for e in &events {
            writer.queue_event(e);
            codec::encode_event(e, &mut plain);
        }
        assert_eq!(writer.pending(), plain.len());
        writer.flush().await.expect("flush");
        assert_eq!(writer.pending(), 0);
        let mut sent = BytesMut::new();
        tokio::time::timeout(std::time::Duration::from_secs(30), async {
            while sent.len() < plain.len() {
                let n = r.read_into(&mut sent).await.expect("read");
                assert!(n > 0, "the pipe closed early");
            }
        })
        .await
        .expect("every queued byte within 30 s");
        assert!(
            sent == plain[..],
            "bytes on the wire differ from encode_event"
        );
    }
}
