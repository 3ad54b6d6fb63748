//! FlowProtocol over a serial line: the byte stream of frames cut into checksummed packets (`flow_lite::line`).
//!
//! A serial line loses and flips bytes, and nothing below us notices. Each write (one or more whole frames) goes
//! out as packets of whole frames, so a damaged packet, which the reader drops and counts, takes whole frames
//! with it and the frames after it still parse: the session survives a bad byte, the frames in that packet are
//! lost as on any lossy link (a command lost that way times out in the caller). The same framing runs on boards
//! through `flow-lite`.
//!
//! [`LineTransport`] puts the framing over any byte stream (a pseudo-terminal in tests); [`SerialTransport`] opens
//! a real line at a baud rate through `tokio-serial`.

use std::io;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use bytes::BytesMut;
use flow_lite::line::{self, Deframed, Deframer};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadHalf, WriteHalf};
use tokio_serial::{SerialPortBuilderExt, SerialStream};

use super::traits::{Transport, TransportRead, TransportWrite};

/// The largest packet body: bigger writes go out as several packets, cut between frames. Small, because a damaged
/// packet loses every frame in it: a writer that batched a second of readings into one packet would lose them all
/// to one flipped bit. A kilobyte keeps a board's receive buffer small too, and costs 6 bytes of framing per
/// packet. A single frame larger than this still goes out whole (the reader's buffer holds one such packet), so
/// nothing is refused here.
pub const PACKET_BODY_MAX: usize = 1024;

/// The reader's packet buffer: one packet of the largest frame a serial peer may send (a line is slow; 1 MiB takes
/// a minute and a half at 115200 baud).
pub const PACKET_BUFFER: usize = line::max_encoded_len(1024 * 1024);

/// What a line has seen, shared with whoever reports it (the hub's metrics, a test).
#[derive(Debug, Default)]
pub struct LineStats {
    /// Intact packets read.
    pub packets: AtomicU64,
    /// Packets dropped as damaged (bad checksum, bad stuffing, too long).
    pub damaged: AtomicU64,
}

impl LineStats {
    pub fn damaged(&self) -> u64 {
        self.damaged.load(Ordering::Relaxed)
    }

    pub fn packets(&self) -> u64 {
        self.packets.load(Ordering::Relaxed)
    }
}

/// FlowProtocol over any byte stream, framed for a lossy line.
#[derive(Debug)]
pub struct LineTransport<S> {
    stream: S,
    peer: String,
    stats: Arc<LineStats>,
}

/// A serial line opened with `tokio-serial`.
pub type SerialTransport = LineTransport<SerialStream>;

impl LineTransport<SerialStream> {
    /// Opens the serial device at `path` (8N1, no flow control) at `baud`.
    pub fn open(path: &Path, baud: u32) -> io::Result<Self> {
        let name = path.to_string_lossy();
        let stream = tokio_serial::new(name.as_ref(), baud)
            .open_native_async()
            .map_err(io::Error::other)?;
        Ok(LineTransport::new(
            stream,
            format!("serial:{}", path.display()),
        ))
    }
}

impl<S> LineTransport<S> {
    pub fn new(stream: S, peer: String) -> Self {
        LineTransport {
            stream,
            peer,
            stats: Arc::default(),
        }
    }

    /// Counts into `stats` (a line's counters that outlive each opening of it).
    pub fn with_stats(mut self, stats: Arc<LineStats>) -> Self {
        self.stats = stats;
        self
    }

    /// The line's counters; they stay readable after the transport is split and gone.
    pub fn stats(&self) -> Arc<LineStats> {
        self.stats.clone()
    }
}

impl<S: AsyncRead + AsyncWrite + Send + 'static> Transport for LineTransport<S> {
    type Reader = LineReader<ReadHalf<S>>;
    type Writer = LineWriter<WriteHalf<S>>;

    fn peer(&self) -> String {
        self.peer.clone()
    }

    fn split(self) -> (Self::Reader, Self::Writer) {
        let (r, w) = tokio::io::split(self.stream);
        (
            LineReader {
                inner: r,
                raw: vec![0; 16 * 1024],
                raw_len: 0,
                raw_at: 0,
                deframer: Deframer::new(vec![0; PACKET_BUFFER].into_boxed_slice()),
                stats: self.stats,
                peer: self.peer,
            },
            LineWriter {
                inner: w,
                out: Vec::new(),
                started: false,
            },
        )
    }
}

/// Reading half: line bytes in, intact packet bodies (whole frames) out.
#[derive(Debug)]
pub struct LineReader<R> {
    inner: R,
    /// Line bytes read but not yet given to the deframer.
    raw: Vec<u8>,
    raw_len: usize,
    raw_at: usize,
    deframer: Deframer<Box<[u8]>>,
    stats: Arc<LineStats>,
    peer: String,
}

impl<R: AsyncRead + Unpin + Send + 'static> TransportRead for LineReader<R> {
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        loop {
            while self.raw_at < self.raw_len {
                let (used, out) = self.deframer.push(&self.raw[self.raw_at..self.raw_len]);
                self.raw_at += used;
                match out {
                    Some(Deframed::Packet(body)) => {
                        self.stats.packets.fetch_add(1, Ordering::Relaxed);
                        buf.extend_from_slice(body);
                        return Ok(body.len());
                    }
                    Some(Deframed::Damaged(why)) => {
                        let n = self.stats.damaged.fetch_add(1, Ordering::Relaxed) + 1;
                        tracing::debug!(peer = %self.peer, ?why, damaged = n, "damaged packet dropped");
                    }
                    None => {}
                }
            }
            self.raw_at = 0;
            self.raw_len = self.inner.read(&mut self.raw).await?;
            if self.raw_len == 0 {
                return Ok(0);
            }
        }
    }
}

/// Writing half: each write's frames go out as packets.
#[derive(Debug)]
pub struct LineWriter<W> {
    inner: W,
    out: Vec<u8>,
    /// Whether the resynchronising zero went out: the first bytes of a line may follow noise.
    started: bool,
}

impl<W: AsyncWrite + Unpin + Send + 'static> TransportWrite for LineWriter<W> {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        self.out.clear();
        if !self.started {
            self.out.push(0);
            self.started = true;
        }
        for body in whole_frame_runs(data, PACKET_BODY_MAX) {
            let at = self.out.len();
            self.out.resize(at + line::max_encoded_len(body.len()), 0);
            let n = line::encode(body, &mut self.out[at..])
                .map_err(|e| io::Error::other(format!("serial framing: {e:?}")))?;
            self.out.truncate(at + n);
        }
        // No flush: the stream has no buffer of its own, and a serial port's flush waits for the line to drain
        // (tcdrain), which would hold the writer for every packet.
        self.inner.write_all(&self.out).await
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        self.inner.shutdown().await
    }
}

/// Cuts `data` (whole frames) into runs of whole frames of at most `max` bytes each; a frame longer than `max` is
/// a run of its own, and bytes that do not parse as a frame header end the last run (the writer only ever holds
/// whole frames).
fn whole_frame_runs(data: &[u8], max: usize) -> impl Iterator<Item = &[u8]> {
    let mut rest = data;
    std::iter::from_fn(move || {
        if rest.is_empty() {
            return None;
        }
        let mut end = 0;
        while end < rest.len() {
            let Some(len) = rest
                .get(end..end + 4)
                .and_then(|b| b.try_into().ok())
                .map(|b: [u8; 4]| u32::from_le_bytes(b) as usize + 4)
            else {
                end = rest.len();
                break;
            };
            if end > 0 && end + len > max {
                break;
            }
            end = (end + len).min(rest.len());
        }
        let (run, tail) = rest.split_at(end);
        rest = tail;
        Some(run)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(body_len: usize, fill: u8) -> Vec<u8> {
        let mut f = ((body_len + 5) as u32).to_le_bytes().to_vec();
        f.push(7);
        f.extend(0u32.to_le_bytes());
        f.extend(std::iter::repeat_n(fill, body_len));
        f
    }

    #[test]
    fn writes_are_cut_between_frames_into_bounded_packets() {
        let frames: Vec<Vec<u8>> = (0..10).map(|i| frame(300, i)).collect();
        let data = frames.concat();
        let runs: Vec<&[u8]> = whole_frame_runs(&data, 1000).collect();
        assert_eq!(runs.concat(), data);
        // 309 bytes a frame: three to a packet.
        assert!(
            runs.iter().all(|r| r.len() <= 1000 && r.len() % 309 == 0),
            "{:?}",
            runs.iter().map(|r| r.len()).collect::<Vec<_>>()
        );
        assert_eq!(runs.len(), 4);
        // A frame larger than a packet goes out alone.
        let big = [frame(10, 1), frame(5000, 2), frame(10, 3)].concat();
        let runs: Vec<usize> = whole_frame_runs(&big, 1000).map(<[u8]>::len).collect();
        assert_eq!(runs, vec![19, 5009, 19]);
    }

    #[tokio::test]
    async fn frames_cross_a_clean_line_whole_and_in_order() {
        let (a, b) = tokio::io::duplex(1 << 20);
        let (_, mut writer) = LineTransport::new(a, "a".into()).split();
        let receiving = LineTransport::new(b, "b".into());
        let stats = receiving.stats();
        let (mut reader, _w) = receiving.split();
        let frames: Vec<Vec<u8>> = (0..20).map(|i| frame(100 + i, i as u8 + 1)).collect();
        for f in &frames {
            writer.write_all(f).await.expect("write");
        }
        let mut got = BytesMut::new();
        tokio::time::timeout(std::time::Duration::from_secs(30), async {
            while got.len() < frames.concat().len() {
                reader.read_into(&mut got).await.expect("read");
            }
        })
        .await
        .expect("every frame within 30 s");
        assert_eq!(&got[..], &frames.concat()[..]);
        assert_eq!((stats.packets(), stats.damaged()), (20, 0));
    }

    #[tokio::test]
    async fn a_damaged_packet_is_counted_and_the_next_frames_arrive_whole() {
        let (mut raw, b) = tokio::io::duplex(1 << 20);
        let receiving = LineTransport::new(b, "b".into());
        let stats = receiving.stats();
        let (mut reader, _w) = receiving.split();
        let mut wire = Vec::new();
        let frames: Vec<Vec<u8>> = (0..3).map(|i| frame(50, i + 1)).collect();
        for f in &frames {
            let mut p = vec![0; line::max_encoded_len(f.len())];
            let n = line::encode(f, &mut p).expect("encode");
            p.truncate(n);
            wire.push(p);
        }
        wire[1][10] ^= 0x10;
        raw.write_all(&wire.concat()).await.expect("write");
        let mut got = BytesMut::new();
        tokio::time::timeout(std::time::Duration::from_secs(30), async {
            while got.len() < 2 * frames[0].len() {
                reader.read_into(&mut got).await.expect("read");
            }
        })
        .await
        .expect("the two whole frames within 30 s");
        assert_eq!(
            &got[..],
            &[frames[0].clone(), frames[2].clone()].concat()[..]
        );
        assert_eq!(stats.damaged(), 1);
    }
}
