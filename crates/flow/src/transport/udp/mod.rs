//! FlowProtocol over UDP (`udp://HOST:PORT`): sessions of datagrams (`datagram.rs`) carrying the same frames as
//! every other transport, with a reliable lane and a best-effort one (`engine.rs`): the writer sends its own frames
//! and the reader takes frames straight from the session's state, a keeper task fires the timers (`session.rs`),
//! and each burst goes out in one system call (`batch.rs`).
//!
//! A client opens a session with a hello padded to 1200 bytes, sent again with back-off until the hub answers with
//! a session id; from then on every datagram carries that id. [`UdpTransport::connect`] is the client's end; the
//! hub builds its end of each session with [`UdpTransport::accepted`], and its demultiplexer puts in the datagrams
//! its one socket received for that session ([`UdpTransport::inbox`]). Either way the halves look like a byte
//! stream of whole frames: the reader hands over whole frames as they are delivered, the writer takes whole frames.

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use bytes::BytesMut;
use tokio::net::UdpSocket;
use tokio::time::Instant;

use super::traits::{Transport, TransportRead, TransportWrite};

pub mod batch;
pub mod datagram;
pub mod engine;
mod session;

use batch::BatchSocket;
use datagram::{Datagram, Kind};
pub use engine::{DEFAULT_MTU, Engine, Settings, UdpStats};
use session::{CLOSE_GRACE, Ended, Session, Source};
pub use session::{DELIVERED_BACKLOG, Inbox};

/// How long a client waits for the hub to answer its hello, sending it again with back-off.
const HELLO_PATIENCE: Duration = Duration::from_secs(5);
/// The most bytes one read hands over.
const READ_MAX: usize = 64 * 1024;

/// One FlowProtocol session over UDP, not yet split.
#[derive(Debug)]
pub struct UdpTransport {
    session: Arc<Session>,
    peer: String,
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
            session: Arc::new(Session::new(
                Engine::client(session, settings, stats.clone(), Instant::now()),
                Arc::new(BatchSocket::new(socket)?),
                None,
                Source::Socket,
                stats,
            )),
            peer: format!("udp:{addr}"),
        })
    }

    /// The hub's end of `session` with the client at `peer`, whose datagrams its demultiplexer puts in through
    /// [`UdpTransport::inbox`]; `budget` is what it may send before it hears more (the hello's size less the
    /// hello-ack's).
    pub fn accepted(
        socket: Arc<BatchSocket>,
        peer: SocketAddr,
        session: u32,
        budget: usize,
        stats: Arc<UdpStats>,
    ) -> Self {
        UdpTransport {
            session: Arc::new(Session::new(
                Engine::hub(
                    session,
                    Settings::default(),
                    stats.clone(),
                    Instant::now(),
                    budget,
                ),
                socket,
                Some(peer),
                Source::Pushed,
                stats,
            )),
            peer: format!("udp:{peer}"),
        }
    }

    /// Where the hub's demultiplexer puts this session's datagrams.
    pub fn inbox(&self) -> Inbox {
        Inbox {
            session: self.session.clone(),
        }
    }

    /// The session's counters; they stay readable after the transport is split and gone.
    pub fn stats(&self) -> Arc<UdpStats> {
        self.session.stats().clone()
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

impl Transport for UdpTransport {
    type Reader = UdpReader;
    type Writer = UdpWriter;

    fn peer(&self) -> String {
        self.peer.clone()
    }

    fn split(self) -> (UdpReader, UdpWriter) {
        tokio::spawn(self.session.clone().keep());
        (
            UdpReader {
                session: self.session.clone(),
                received: None,
            },
            UdpWriter {
                session: self.session,
                shut: false,
            },
        )
    }
}

/// Reading half: whole frames as the session delivers them.
#[derive(Debug)]
pub struct UdpReader {
    session: Arc<Session>,
    /// A client's receive buffers, made at its first wait on the socket.
    received: Option<Box<batch::Received>>,
}

impl TransportRead for UdpReader {
    async fn read_into(&mut self, buf: &mut BytesMut) -> io::Result<usize> {
        let s = &self.session;
        loop {
            let change = s.change();
            let (frames, output) = {
                let engine = s.engine();
                (engine.frames_waiting(), engine.has_output())
            };
            if frames > 0 || output {
                // The acknowledgement of what is read goes out first (on the hub nobody else sends it); nothing is
                // taken before the last await, so a read given up there loses nothing.
                s.flush().await;
            }
            if frames > 0 {
                let mut engine = s.engine();
                let mut n = 0;
                while n < READ_MAX {
                    let Some(frame) = engine.poll_frame() else {
                        break;
                    };
                    n += frame.len();
                    buf.extend_from_slice(&frame);
                }
                drop(engine);
                if frames >= DELIVERED_BACKLOG {
                    s.made_room();
                }
                return Ok(n);
            }
            match s.ended() {
                Some(Ended::Closed) => return Ok(0),
                Some(Ended::Failed(why)) => {
                    return Err(io::Error::new(io::ErrorKind::ConnectionAborted, why));
                }
                None if s.source() == Source::Socket => {
                    // The frame comes through this task: the reader reads the socket while it waits.
                    let received = self.received.get_or_insert_with(Box::default);
                    let _listening = s.listen();
                    tokio::select! {
                        () = change => {}
                        () = s.receive(received) => {}
                    }
                }
                None => change.await,
            }
        }
    }
}

impl Drop for UdpReader {
    fn drop(&mut self) {
        self.session.reader_gone();
    }
}

/// Writing half: whole frames to the session.
#[derive(Debug)]
pub struct UdpWriter {
    session: Arc<Session>,
    /// `shutdown` ran: nothing more may be written.
    shut: bool,
}

impl UdpWriter {
    fn gone(&self) -> io::Error {
        let why = match self.session.ended() {
            Some(Ended::Failed(why)) => why,
            _ => "udp session closed".into(),
        };
        io::Error::new(io::ErrorKind::BrokenPipe, why)
    }
}

impl TransportWrite for UdpWriter {
    async fn write_all(&mut self, data: &[u8]) -> io::Result<()> {
        let s = &self.session;
        loop {
            let change = s.change();
            if self.shut || s.ended().is_some() {
                return Err(self.gone());
            }
            // Taken at once when the window has room, else after acknowledgements have freed it.
            let taken = {
                let mut engine = s.engine();
                engine.can_take().then(|| engine.send_frames(data))
            };
            match taken {
                Some(Ok(())) => {
                    s.flush().await;
                    s.rearm();
                    return Ok(());
                }
                Some(Err(why)) => {
                    s.fail(why);
                    return Err(self.gone());
                }
                None => change.await,
            }
        }
    }

    async fn shutdown(&mut self) -> io::Result<()> {
        if self.shut {
            return Ok(());
        }
        self.shut = true;
        let s = &self.session;
        s.writer_done();
        // The keeper sends what is unacknowledged, then the close; the session ends on its own if this wait is cut.
        let _ = tokio::time::timeout(CLOSE_GRACE + Duration::from_millis(500), async {
            loop {
                let change = s.change();
                if s.ended().is_some() {
                    return;
                }
                change.await;
            }
        })
        .await;
        Ok(())
    }
}

impl Drop for UdpWriter {
    /// A writer dropped without `shutdown` still has the keeper close the session gracefully.
    fn drop(&mut self) {
        if !self.shut {
            self.session.writer_done();
        }
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
        let socket = Arc::new(
            BatchSocket::new(UdpSocket::bind("127.0.0.1:0").await.expect("bind")).expect("batches"),
        );
        let addr = socket.socket().local_addr().expect("addr");
        let (give, take) = tokio::sync::oneshot::channel();
        tokio::spawn(async move {
            let mut give = Some(give);
            let mut inbound: Option<(SocketAddr, Inbox)> = None;
            let mut received = batch::Received::default();
            while socket.recv(&mut received).await.is_ok() {
                for (from, bytes) in received.datagrams() {
                    let Ok(d) = Datagram::decode(bytes) else {
                        continue;
                    };
                    if d.kind == Kind::Hello {
                        let ack = Datagram::bare(Kind::HelloAck, 77, d.session).to_vec();
                        let t = UdpTransport::accepted(
                            socket.clone(),
                            from,
                            77,
                            bytes.len() - ack.len(),
                            Arc::default(),
                        );
                        if let Some(give) = give.take() {
                            inbound = Some((from, t.inbox()));
                            let _ = give.send(t);
                        }
                        let _ = socket.socket().send_to(&ack, from).await;
                    } else if let Some((peer, inbox)) = &inbound
                        && *peer == from
                    {
                        inbox.push(bytes);
                    }
                }
            }
        });
        (addr, take)
    }

    /// A client connected to [`one_session_hub`], both ends split, after the client's login reached the hub's end
    /// (before login the hub's end may not answer more than it heard). Returns the hub's reader and writer, then
    /// the client's.
    async fn logged_in_pair() -> (UdpReader, UdpWriter, UdpReader, UdpWriter) {
        let (addr, hub) = one_session_hub().await;
        let client = UdpTransport::connect(&addr.to_string())
            .await
            .expect("connect");
        let hub = hub.await.expect("session");
        let (mut hub_r, hub_w) = hub.split();
        let (cli_r, mut cli_w) = client.split();
        let login = frame(op::LOGIN, 1, 60);
        cli_w.write_all(&login).await.expect("write");
        assert_eq!(read_exactly(&mut hub_r, login.len()).await, login);
        (hub_r, hub_w, cli_r, cli_w)
    }

    #[tokio::test]
    async fn frames_cross_a_real_socket_whole_both_ways_and_a_close_ends_the_peer() {
        let (mut hub_r, mut hub_w, mut cli_r, mut cli_w) = logged_in_pair().await;
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

    /// The keeper moves a session that neither half waits on: with its reader never read, more reliable frames
    /// than the window holds go out (acknowledgements free it), arrive in order, and the close still ends the peer.
    #[tokio::test]
    async fn a_session_whose_reader_is_never_read_still_sends_more_than_a_window_and_closes() {
        let (mut hub_r, _hub_w, _cli_r, mut cli_w) = logged_in_pair().await;
        // Twice the window of calls, each its own write, while the hub's end is read on a task of its own.
        let calls: Vec<Vec<u8>> = (0..2 * Settings::default().window as u32)
            .map(|i| frame(op::CALL, i + 2, 100))
            .collect();
        let want = calls.concat();
        let read = tokio::spawn(async move {
            let got = read_exactly(&mut hub_r, want.len()).await;
            assert!(got == want, "the calls arrived changed or out of order");
            hub_r
        });
        let writes = tokio::time::timeout(Duration::from_secs(30), async {
            for c in &calls {
                cli_w.write_all(c).await.expect("write");
            }
        })
        .await;
        assert!(writes.is_ok(), "the writer was stalled by a full window");
        let mut hub_r = read.await.expect("reader");
        cli_w.shutdown().await.expect("shutdown");
        let mut rest = BytesMut::new();
        let end = tokio::time::timeout(Duration::from_secs(30), hub_r.read_into(&mut rest)).await;
        assert_eq!(end.expect("the close reached the hub").expect("end"), 0);
    }
}
