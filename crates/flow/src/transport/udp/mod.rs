//! FlowProtocol over UDP (`udp://HOST:PORT`): sessions of datagrams (`datagram.rs`) carrying the same frames as
//! every other transport, with a reliable lane and a best-effort one (`engine.rs`), driven by one task per session
//! that sends each burst in one system call (`batch.rs`).
//!
//! A client opens a session with a hello padded to 1200 bytes, sent again with back-off until the hub answers with
//! a session id; from then on every datagram carries that id. [`UdpTransport::connect`] is the client's end; the
//! hub builds its end of each session with [`UdpTransport::accepted`], feeding it the datagrams its one socket
//! received for that session. Either way the halves look like a byte stream of whole frames: the reader hands
//! over whole frames as they are delivered, the writer takes whole frames.

use std::io;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bytes::{Bytes, BytesMut};
use tokio::net::UdpSocket;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use super::traits::{Transport, TransportRead, TransportWrite};

pub mod batch;
pub mod datagram;
pub mod engine;

use datagram::{Datagram, Kind};
pub use engine::{DEFAULT_MTU, Engine, Settings, UdpStats};

/// How long a client waits for the hub to answer its hello, sending it again with back-off.
const HELLO_PATIENCE: Duration = Duration::from_secs(5);
/// Frames delivered and not yet read before the session stops taking datagrams (they wait in the socket or the
/// hub's per-session queue, and beyond that are dropped and sent again).
const DELIVERED_BACKLOG: usize = 256;
/// Writes queued for the driver before a writer waits.
const WRITE_QUEUE: usize = 64;
/// How long a closing writer waits for its reliable data to be acknowledged.
const CLOSE_GRACE: Duration = Duration::from_secs(2);

/// Where a session's datagrams come from.
#[derive(Debug)]
enum Source {
    /// A client's connected socket.
    Socket,
    /// The hub's demultiplexer, which checked the session id and the address.
    Queue(mpsc::Receiver<Bytes>),
}

/// One FlowProtocol session over UDP, not yet split.
#[derive(Debug)]
pub struct UdpTransport {
    engine: Engine,
    socket: Arc<UdpSocket>,
    /// The peer's address when the socket is shared (the hub); `None` on a client's connected socket.
    to: Option<SocketAddr>,
    source: Source,
    peer: String,
    stats: Arc<UdpStats>,
}

impl UdpTransport {
    /// Opens a session with the hub at `hostport`.
    pub async fn connect(hostport: &str) -> io::Result<Self> {
        Self::connect_with(hostport, Settings::default(), Arc::default()).await
    }

    /// Opens a session with `settings`, counting into `stats`.
    pub async fn connect_with(
        hostport: &str,
        settings: Settings,
        stats: Arc<UdpStats>,
    ) -> io::Result<Self> {
        let addr = tokio::net::lookup_host(hostport)
            .await?
            .next()
            .ok_or_else(|| {
                io::Error::new(io::ErrorKind::NotFound, format!("{hostport}: no address"))
            })?;
        let socket = UdpSocket::bind(if addr.is_ipv4() {
            "0.0.0.0:0"
        } else {
            "[::]:0"
        })
        .await?;
        socket.connect(addr).await?;
        let nonce = random_u32() | 1;
        let hello = Datagram::bare(Kind::Hello, nonce, 0).to_vec();
        let began = Instant::now();
        let mut wait = settings.rto_min.max(Duration::from_millis(50));
        let mut buf = vec![0u8; 2048];
        let session = 'hello: loop {
            socket.send(&hello).await?;
            let until = Instant::now() + wait;
            while let Ok(got) = tokio::time::timeout_at(until, socket.recv(&mut buf)).await {
                let n = got?;
                match Datagram::decode(&buf[..n]) {
                    Ok(d) if d.kind == Kind::HelloAck && d.seq == nonce => break 'hello d.session,
                    Ok(_) => UdpStats::add(&stats.spoofed, 1),
                    Err(_) => UdpStats::add(&stats.malformed, 1),
                }
            }
            if began.elapsed() >= HELLO_PATIENCE {
                return Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!(
                        "udp://{hostport}: no answer to hello within {} s",
                        HELLO_PATIENCE.as_secs()
                    ),
                ));
            }
            wait = (wait * 2).min(settings.rto_max);
        };
        Ok(UdpTransport {
            engine: Engine::client(session, settings, stats.clone(), Instant::now()),
            socket: Arc::new(socket),
            to: None,
            source: Source::Socket,
            peer: format!("udp:{addr}"),
            stats,
        })
    }

    /// The hub's end of `session` with the client at `peer`, whose datagrams come through `inbound`; `budget` is
    /// what it may send before it hears more (the hello's size less the hello-ack's).
    pub fn accepted(
        socket: Arc<UdpSocket>,
        peer: SocketAddr,
        session: u32,
        inbound: mpsc::Receiver<Bytes>,
        budget: usize,
        stats: Arc<UdpStats>,
    ) -> Self {
        UdpTransport {
            engine: Engine::hub(
                session,
                Settings::default(),
                stats.clone(),
                Instant::now(),
                budget,
            ),
            socket,
            to: Some(peer),
            source: Source::Queue(inbound),
            peer: format!("udp:{peer}"),
            stats,
        }
    }

    /// The session's counters; they stay readable after the transport is split and gone.
    pub fn stats(&self) -> Arc<UdpStats> {
        self.stats.clone()
    }
}

/// A random `u32` from the standard library's randomly keyed hasher (this crate has no random number generator of
/// its own); a nonce, not a secret.
fn random_u32() -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos()),
    );
    h.write_u32(std::process::id());
    h.finish() as u32
}

/// Why a session ended, when it failed; shared by the driver and both halves.
type End = Arc<Mutex<Option<String>>>;

fn ended(end: &End) -> Option<String> {
    end.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone()
}

impl Transport for UdpTransport {
    type Reader = UdpReader;
    type Writer = UdpWriter;

    fn peer(&self) -> String {
        self.peer.clone()
    }

    fn split(self) -> (UdpReader, UdpWriter) {
        let (frames_tx, frames_rx) = mpsc::channel(DELIVERED_BACKLOG);
        let (writes_tx, writes_rx) = mpsc::channel(WRITE_QUEUE);
        let end = End::default();
        let driver = Driver {
            engine: self.engine,
            socket: self.socket,
            to: self.to,
            source: self.source,
            frames: frames_tx,
            writes: writes_rx,
            stats: self.stats,
        };
        let task = tokio::spawn(driver.run(end.clone()));
        (
            UdpReader {
                frames: frames_rx,
                end: end.clone(),
            },
            UdpWriter {
                writes: Some(writes_tx),
                end,
                task: Some(task),
            },
        )
    }
}

/// The task that owns a session's engine: datagrams in and out, timers, and the halves' queues.
#[derive(Debug)]
struct Driver {
    engine: Engine,
    socket: Arc<UdpSocket>,
    to: Option<SocketAddr>,
    source: Source,
    frames: mpsc::Sender<Bytes>,
    writes: mpsc::Receiver<Bytes>,
    stats: Arc<UdpStats>,
}

impl Driver {
    async fn run(mut self, end: End) {
        if let Err(why) = self.serve().await {
            tracing::debug!(session = self.engine.session(), "udp session failed: {why}");
            *end.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(why);
        }
    }

    /// Sends a burst of datagrams in as few system calls as the kernel takes (`batch.rs`).
    async fn send(&self, datagrams: &[impl AsRef<[u8]>]) -> Result<(), String> {
        match batch::send_all(&self.socket, self.to, datagrams).await {
            Ok(sent) => {
                batch::count(sent, &self.stats.sent, &self.stats.send_calls);
                Ok(())
            }
            // A connected socket hears of a closed port: nobody listens there any more.
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => Err(format!("udp: {e}")),
            // Anything else (the socket's readiness failing) loses the burst, as the wire could.
            Err(_) => Ok(()),
        }
    }

    async fn serve(&mut self) -> Result<(), String> {
        let mut writes_open = true;
        let mut reader_open = true;
        let mut closing_since: Option<Instant> = None;
        let mut buf = vec![0u8; 65536];
        let mut burst: Vec<Bytes> = Vec::new();
        loop {
            let now = Instant::now();
            // Everything the engine has to send now goes out together: a frame's fragments, acknowledgements.
            burst.clear();
            while let Some(d) = self.engine.poll_send(now) {
                burst.push(d);
            }
            if !burst.is_empty() {
                self.send(&burst).await?;
            }
            if !reader_open {
                while self.engine.poll_frame().is_some() {}
            }
            if !writes_open {
                let since = *closing_since.get_or_insert(now);
                if self.engine.all_acknowledged() || now >= since + CLOSE_GRACE || !reader_open {
                    let close = self.engine.close_datagram();
                    // Twice: a lost close costs the peer its idle timeout.
                    self.send(&[&close, &close]).await?;
                    return Ok(());
                }
            }
            if self.engine.peer_closed() && (self.engine.frames_waiting() == 0 || !reader_open) {
                return Ok(());
            }
            let deadline = if closing_since.is_some() {
                self.engine.deadline().min(now + Duration::from_millis(50))
            } else {
                self.engine.deadline()
            };
            let has_frames = reader_open && self.engine.frames_waiting() > 0;
            let may_receive = self.engine.frames_waiting() < DELIVERED_BACKLOG;
            tokio::select! {
                permit = self.frames.reserve(), if has_frames => match permit {
                    Ok(permit) => {
                        if let Some(f) = self.engine.poll_frame() {
                            permit.send(f);
                        }
                        while self.engine.frames_waiting() > 0 {
                            let Ok(permit) = self.frames.try_reserve() else { break };
                            if let Some(f) = self.engine.poll_frame() {
                                permit.send(f);
                            }
                        }
                    }
                    Err(_) => reader_open = false,
                },
                got = recv(&self.socket, &mut self.source, &mut buf), if may_receive => {
                    let bytes = got?;
                    take(&mut self.engine, &self.stats, &bytes)?;
                    // What else is queued now goes in before one acknowledgement answers it all.
                    for _ in 0..64 {
                        let Some(bytes) = try_recv(&self.socket, &mut self.source, &mut buf)? else { break };
                        take(&mut self.engine, &self.stats, &bytes)?;
                    }
                }
                w = self.writes.recv(), if writes_open && self.engine.can_take() => match w {
                    Some(data) => self.engine.send_frames(&data)?,
                    None => writes_open = false,
                },
                () = tokio::time::sleep_until(deadline) => self.engine.on_timer(Instant::now())?,
            }
        }
    }
}

/// Takes one received datagram into `engine`.
fn take(engine: &mut Engine, stats: &UdpStats, bytes: &[u8]) -> Result<(), String> {
    match Datagram::decode(bytes) {
        Err(_) => UdpStats::add(&stats.malformed, 1),
        Ok(d) if d.session != engine.session() || d.kind == Kind::Hello => {
            // A late hello-ack on the client is harmless; anything else names another session.
            if d.kind != Kind::HelloAck {
                UdpStats::add(&stats.spoofed, 1);
            }
        }
        Ok(d) => engine.on_datagram(&d, Instant::now())?,
    }
    Ok(())
}

async fn recv(socket: &UdpSocket, source: &mut Source, buf: &mut [u8]) -> Result<Bytes, String> {
    match source {
        Source::Socket => match socket.recv(buf).await {
            Ok(n) => Ok(Bytes::copy_from_slice(&buf[..n])),
            Err(e) => Err(format!("udp: {e}")),
        },
        Source::Queue(rx) => rx
            .recv()
            .await
            .ok_or_else(|| "the hub's UDP edge ended the session".to_string()),
    }
}

fn try_recv(
    socket: &UdpSocket,
    source: &mut Source,
    buf: &mut [u8],
) -> Result<Option<Bytes>, String> {
    match source {
        Source::Socket => match socket.try_recv(buf) {
            Ok(n) => Ok(Some(Bytes::copy_from_slice(&buf[..n]))),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => Ok(None),
            Err(e) => Err(format!("udp: {e}")),
        },
        Source::Queue(rx) => Ok(rx.try_recv().ok()),
    }
}

/// Reading half: whole frames as the session delivers them.
#[derive(Debug)]
pub struct UdpReader {
    frames: mpsc::Receiver<Bytes>,
    end: End,
}

impl TransportRead for UdpReader {
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        let Some(first) = self.frames.recv().await else {
            return match ended(&self.end) {
                Some(why) => Err(io::Error::new(io::ErrorKind::ConnectionAborted, why)),
                None => Ok(0),
            };
        };
        let mut n = first.len();
        buf.extend_from_slice(&first);
        while n < 64 * 1024 {
            let Ok(more) = self.frames.try_recv() else {
                break;
            };
            n += more.len();
            buf.extend_from_slice(&more);
        }
        Ok(n)
    }
}

/// Writing half: whole frames to the session.
#[derive(Debug)]
pub struct UdpWriter {
    writes: Option<mpsc::Sender<Bytes>>,
    end: End,
    task: Option<JoinHandle<()>>,
}

impl UdpWriter {
    fn gone(&self) -> io::Error {
        io::Error::new(
            io::ErrorKind::BrokenPipe,
            ended(&self.end).unwrap_or_else(|| "udp session closed".into()),
        )
    }
}

impl TransportWrite for UdpWriter {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        let Some(writes) = &self.writes else {
            return Err(self.gone());
        };
        if writes.send(Bytes::copy_from_slice(data)).await.is_err() {
            return Err(self.gone());
        }
        Ok(())
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        self.writes = None;
        if let Some(task) = self.task.take() {
            // The driver sends what is unacknowledged, then the close; it ends on its own if this wait is cut.
            let _ = tokio::time::timeout(CLOSE_GRACE + Duration::from_millis(500), task).await;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::message::op;

    fn frame(op_code: u8, req: u32, body_len: usize) -> Vec<u8> {
        let mut f = ((body_len + 5) as u32).to_le_bytes().to_vec();
        f.push(op_code);
        f.extend(req.to_le_bytes());
        f.extend((0..body_len).map(|i| (i as u32 * 7 + req) as u8));
        f
    }

    /// Reads until `want` bytes came, within one deadline for them all.
    async fn read_exactly(reader: &mut UdpReader, want: usize) -> Vec<u8> {
        let mut got = BytesMut::new();
        let read = tokio::time::timeout(std::time::Duration::from_secs(30), async {
            while got.len() < want {
                let n = reader.read_into(&mut got).await.expect("read");
                assert!(n > 0, "closed after {} of {want} bytes", got.len());
            }
        })
        .await;
        assert!(read.is_ok(), "{} of {want} bytes within 30 s", got.len());
        got.to_vec()
    }

    /// A one-session hub end on a real socket: answers the first hello and feeds the session its datagrams.
    async fn one_session_hub() -> (SocketAddr, tokio::sync::oneshot::Receiver<UdpTransport>) {
        let socket = Arc::new(UdpSocket::bind("127.0.0.1:0").await.expect("bind"));
        let addr = socket.local_addr().expect("addr");
        let (give, take) = tokio::sync::oneshot::channel();
        tokio::spawn(async move {
            let mut give = Some(give);
            let mut inbound: Option<(SocketAddr, mpsc::Sender<Bytes>)> = None;
            let mut buf = vec![0u8; 65536];
            while let Ok((n, from)) = socket.recv_from(&mut buf).await {
                let Ok(d) = Datagram::decode(&buf[..n]) else {
                    continue;
                };
                if d.kind == Kind::Hello {
                    let ack = Datagram::bare(Kind::HelloAck, 77, d.session).to_vec();
                    let (tx, rx) = mpsc::channel(512);
                    let t = UdpTransport::accepted(
                        socket.clone(),
                        from,
                        77,
                        rx,
                        n - ack.len(),
                        Arc::default(),
                    );
                    if let Some(give) = give.take() {
                        let _ = give.send(t);
                        inbound = Some((from, tx));
                    }
                    let _ = socket.send_to(&ack, from).await;
                } else if let Some((peer, tx)) = &inbound
                    && *peer == from
                {
                    let _ = tx.send(Bytes::copy_from_slice(&buf[..n])).await;
                }
            }
        });
        (addr, take)
    }

    #[tokio::test]
    async fn frames_cross_a_real_socket_whole_both_ways_and_a_close_ends_the_peer() {
        let (addr, hub) = one_session_hub().await;
        let client = UdpTransport::connect(&addr.to_string())
            .await
            .expect("connect");
        let hub = hub.await.expect("session");
        let (mut hub_r, mut hub_w) = hub.split();
        let (mut cli_r, mut cli_w) = client.split();
        // Before login the hub's end could not answer more than it heard: log in first.
        let login = frame(op::LOGIN, 1, 60);
        cli_w.write_all(&login).await.expect("write");
        assert_eq!(read_exactly(&mut hub_r, login.len()).await, login);
        let ok = frame(op::REPLY, 1, 1);
        hub_w.write_all(&ok).await.expect("write");
        assert_eq!(read_exactly(&mut cli_r, ok.len()).await, ok);
        // Reliable frames of one and of many datagrams, in one write, arrive whole and in order.
        let calls: Vec<u8> = [
            frame(op::CALL, 2, 10),
            frame(op::CALL, 3, 50_000),
            frame(op::PING, 4, 0),
        ]
        .concat();
        cli_w.write_all(&calls).await.expect("write");
        assert_eq!(read_exactly(&mut hub_r, calls.len()).await, calls);
        let data = frame(op::DATA, 0, 9000);
        hub_w.write_all(&data).await.expect("write");
        assert_eq!(read_exactly(&mut cli_r, data.len()).await, data);
        cli_w.shutdown().await.expect("shutdown");
        let mut rest = BytesMut::new();
        assert_eq!(hub_r.read_into(&mut rest).await.expect("end"), 0);
    }
}
