//! A UDP session's state shared by its two halves and its keeper task, with no queue between them.
//!
//! The writer puts its frames into the engine and sends the burst itself. The reader takes frames straight out of
//! the engine. On the hub the edge's demultiplexer puts each datagram into the engine ([`Inbox`]) and wakes the
//! reader only when there is something to read or send: a frame goes from the socket to the connection with one
//! wake-up. On a client the reader waiting for a frame reads the socket itself ([`Session::receive`]), so a frame
//! reaches it with no wake-up between tasks. The keeper task ([`Session::keep`]) fires the engine's timers
//! (retransmission, missing fragments asked for, keepalive, the idle end), reads a client's socket while the reader
//! does not (acknowledgements for the writer while the application is busy), and closes the session gracefully once
//! the writer is done.
//! The engine's lock (`std::sync::Mutex`) is never held across an `await`.

use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use bytes::Bytes;
use tokio::sync::Notify;
use tokio::time::Instant;

use super::batch::{self, BatchSocket, Received};
use super::datagram::{Datagram, Kind};
use super::engine::{Engine, UdpStats};

/// Frames delivered and not yet read before the session stops taking datagrams (they wait in the socket, or on
/// the hub are dropped and counted; the sender's retransmission covers reliable data).
pub const DELIVERED_BACKLOG: usize = 256;
/// Receives (each of several datagrams) taken from the socket at once, before one acknowledgement answers them all.
const RECEIVE_BURST: usize = 16;
/// How long a closing writer waits for its reliable data to be acknowledged.
pub(super) const CLOSE_GRACE: Duration = Duration::from_secs(2);

/// Where a session's datagrams come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Source {
    /// A client's connected socket, read by the reader while it waits for a frame, else by the keeper.
    Socket,
    /// The hub's demultiplexer, which checked the session id and the address and puts them in ([`Inbox`]).
    Pushed,
}

/// Who takes a datagram into the engine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Taker {
    /// The hub's demultiplexer, through [`Inbox`].
    Edge,
    /// A client's keeper, reading the socket while the reader does not.
    Keeper,
    /// A client's reader, reading the socket itself while it waits for a frame.
    Reader,
}

/// One session's state.
#[derive(Debug)]
pub(super) struct Session {
    engine: Mutex<Engine>,
    socket: Arc<BatchSocket>,
    /// The peer's address when the socket is shared (the hub); `None` on a client's connected socket.
    to: Option<SocketAddr>,
    source: Source,
    stats: Arc<UdpStats>,
    /// Held while a burst goes out, so that bursts leave in the engine's order.
    sending: tokio::sync::Mutex<()>,
    /// For the halves: frames or room arrived, the session ended.
    changed: Notify,
    /// For the keeper: its deadline moved earlier, the reader made room, the writer is done, the session ended.
    keeper: Notify,
    /// The deadline the keeper sleeps until.
    armed: Mutex<Option<Instant>>,
    /// Why the session failed, once it has.
    failure: Mutex<Option<String>>,
    /// The writer is done (shut down or dropped): the keeper closes the session.
    closing: AtomicBool,
    /// The close went out: the session is over for both halves.
    closed: AtomicBool,
    /// The reader is gone: frames delivered from now on are dropped.
    reader_gone: AtomicBool,
    /// A client's reader waits on the socket itself: the keeper leaves the socket to it, so that a frame goes from
    /// the socket to the reader without a hand-over between tasks.
    listening: AtomicBool,
}

/// How a session ended, as its halves see it.
pub(super) enum Ended {
    /// Closed by either side: no more frames.
    Closed,
    /// Failed, with the reason.
    Failed(String),
}

impl Session {
    pub(super) fn new(
        engine: Engine,
        socket: Arc<BatchSocket>,
        to: Option<SocketAddr>,
        source: Source,
        stats: Arc<UdpStats>,
    ) -> Self {
        Session {
            engine: Mutex::new(engine),
            socket,
            to,
            source,
            stats,
            sending: tokio::sync::Mutex::new(()),
            changed: Notify::new(),
            keeper: Notify::new(),
            armed: Mutex::new(None),
            failure: Mutex::new(None),
            closing: AtomicBool::new(false),
            closed: AtomicBool::new(false),
            reader_gone: AtomicBool::new(false),
            listening: AtomicBool::new(false),
        }
    }

    pub(super) fn source(&self) -> Source {
        self.source
    }

    /// The reader waits on a client's socket until the returned guard is dropped (a frame came, or the read was
    /// given up): the keeper reads it again from then on.
    pub(super) fn listen(&self) -> Listening<'_> {
        self.listening.store(true, Ordering::Release);
        Listening { session: self }
    }

    /// Waits for datagrams on a client's socket and takes them into the engine, as the reader (cancel-safe: nothing
    /// is taken before the socket has data).
    pub(super) async fn receive(&self, received: &mut Received) {
        match self.socket.recv(received).await {
            Ok(()) => self.wake_for(self.take_all(received, Taker::Reader)),
            Err(e) => self.fail(format!("udp: {e}")),
        }
    }

    pub(super) fn engine(&self) -> MutexGuard<'_, Engine> {
        lock(&self.engine)
    }

    pub(super) fn stats(&self) -> &Arc<UdpStats> {
        &self.stats
    }

    /// A wake-up for the halves' next change, registered now: a change between a check and the wait is not missed.
    pub(super) fn change(&self) -> std::pin::Pin<Box<tokio::sync::futures::Notified<'_>>> {
        let mut n = Box::pin(self.changed.notified());
        n.as_mut().enable();
        n
    }

    /// Whether (and how) the session is over: failed, closed by the writer, or closed by the peer.
    pub(super) fn ended(&self) -> Option<Ended> {
        if let Some(why) = lock(&self.failure).clone() {
            return Some(Ended::Failed(why));
        }
        (self.closed.load(Ordering::Acquire) || self.engine().peer_closed())
            .then_some(Ended::Closed)
    }

    /// Ends the session with `why` (the first reason stays) and wakes everyone.
    pub(super) fn fail(&self, why: String) {
        {
            let mut failure = lock(&self.failure);
            if failure.is_none() {
                tracing::debug!(
                    session = self.engine().session(),
                    "udp session failed: {why}"
                );
                *failure = Some(why);
            }
        }
        self.wake_all();
    }

    fn wake_all(&self) {
        self.changed.notify_waiters();
        self.keeper.notify_one();
    }

    /// The writer is done: the keeper closes the session once what was sent is acknowledged.
    pub(super) fn writer_done(&self) {
        self.closing.store(true, Ordering::Release);
        self.keeper.notify_one();
    }

    pub(super) fn reader_gone(&self) {
        self.reader_gone.store(true, Ordering::Release);
        while self.engine().poll_frame().is_some() {}
        self.keeper.notify_one();
    }

    /// The reader took frames: a keeper that stopped reading at the backlog may read again.
    pub(super) fn made_room(&self) {
        self.keeper.notify_one();
    }

    /// Sends everything the engine has to send now, in one burst.
    pub(super) async fn flush(&self) {
        let _order = self.sending.lock().await;
        let burst: Vec<Bytes> = {
            let mut engine = self.engine();
            let now = Instant::now();
            std::iter::from_fn(|| engine.poll_send(now)).collect()
        };
        if !burst.is_empty() {
            self.send(&burst).await;
        }
    }

    /// Sends `datagrams` in as few system calls as the kernel takes (`batch.rs`).
    async fn send(&self, datagrams: &[impl AsRef<[u8]>]) {
        match self.socket.send_all(self.to, datagrams).await {
            Ok(sent) => batch::count(sent, &self.stats.sent, &self.stats.send_calls),
            // A connected socket hears of a closed port: nobody listens there any more.
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => {
                self.fail(format!("udp: {e}"));
            }
            // Anything else (the socket's readiness failing) loses the burst, as the wire could.
            Err(_) => {}
        }
    }

    /// After a write has been sent (its reliable datagrams in flight with their retransmission times) or a datagram
    /// pushed in (a frame begun): wakes the keeper when the engine now has work due before the deadline it sleeps
    /// until.
    pub(super) fn rearm(&self) {
        // Read under the engine's lock, under which the keeper also sets what it sleeps until: no change is missed
        // between the two (a notification the keeper is not yet waiting for is kept for it).
        let (deadline, armed) = {
            let engine = self.engine();
            (engine.deadline(), *lock(&self.armed))
        };
        if armed.is_some_and(|armed| deadline < armed) {
            self.keeper.notify_one();
        }
    }

    /// The keeper: runs until the session has closed or failed. Fires the engine's timers, reads a client's
    /// socket, sends what is due, and closes the session once the writer is done (after its reliable data is
    /// acknowledged, for at most [`CLOSE_GRACE`]).
    pub(super) async fn keep(self: Arc<Self>) {
        // The hub's sessions are put their datagrams by the edge: only a client's keeper needs receive buffers.
        let mut received = Received::with_buffers(match self.source {
            Source::Socket => batch::RECEIVE_BUFFERS,
            Source::Pushed => 0,
        });
        let mut closing_since: Option<Instant> = None;
        loop {
            if lock(&self.failure).is_some() {
                return;
            }
            let now = Instant::now();
            let (deadline, waiting, acknowledged, peer_closed) = {
                let engine = self.engine();
                let deadline = engine.deadline();
                *lock(&self.armed) = Some(deadline);
                (
                    deadline,
                    engine.frames_waiting(),
                    engine.all_acknowledged(),
                    engine.peer_closed(),
                )
            };
            if self.closing.load(Ordering::Acquire) {
                let since = *closing_since.get_or_insert(now);
                if acknowledged
                    || now >= since + CLOSE_GRACE
                    || self.reader_gone.load(Ordering::Acquire)
                {
                    let close = self.engine().close_datagram();
                    // Twice: a lost close costs the peer its idle timeout.
                    self.send(&[&close, &close]).await;
                    self.closed.store(true, Ordering::Release);
                    self.wake_all();
                    return;
                }
            }
            if peer_closed && (waiting == 0 || self.reader_gone.load(Ordering::Acquire)) {
                self.wake_all();
                return;
            }
            let deadline = match closing_since {
                Some(_) => deadline.min(now + Duration::from_millis(50)),
                None => deadline,
            };
            let receive = self.source == Source::Socket
                && waiting < DELIVERED_BACKLOG
                && !self.listening.load(Ordering::Acquire);
            tokio::select! {
                got = self.socket.recv(&mut received), if receive => match got {
                    Ok(()) => {
                        let mut news = self.take_all(&received, Taker::Keeper).news;
                        for _ in 1..RECEIVE_BURST {
                            match self.socket.try_recv(&mut received) {
                                Ok(()) => news |= self.take_all(&received, Taker::Keeper).news,
                                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                                Err(e) => {
                                    self.fail(format!("udp: {e}"));
                                    break;
                                }
                            }
                        }
                        if news {
                            self.changed.notify_waiters();
                        }
                    }
                    Err(e) => self.fail(format!("udp: {e}")),
                },
                () = self.keeper.notified() => {}
                () = tokio::time::sleep_until(deadline) => {
                    let fired = self.engine().on_timer(Instant::now());
                    if let Err(why) = fired {
                        self.fail(why);
                    }
                }
            }
            self.flush().await;
        }
    }

    /// Wakes the tasks that datagrams taken by the edge or the reader ask for. A fragment of a frame still incomplete
    /// wakes no half (a 52 KB picture is 44 datagrams and one wake-up); a goodbye ends the keeper too, and a frame
    /// begun asks for its missing fragments after `nack_delay`, which may be sooner than the keeper sleeps until.
    fn wake_for(&self, taken: Taken) {
        if taken.news {
            self.changed.notify_waiters();
        }
        if taken.peer_closed || taken.sooner {
            self.keeper.notify_one();
        }
    }

    /// Takes the datagrams of a client socket's receive into the engine; says what they ask of the tasks.
    fn take_all(&self, received: &Received, taker: Taker) -> Taken {
        received.count(&self.stats.received, &self.stats.receive_calls);
        received
            .datagrams()
            .fold(Taken::default(), |all, (_, d)| all.and(self.take(d, taker)))
    }

    /// Takes one received datagram into the engine, all under one hold of its lock, and says what it asks of the
    /// session's tasks. A datagram `Pushed` by the hub's edge is dropped and counted when the reader has fallen
    /// [`DELIVERED_BACKLOG`] frames behind (a client's keeper stops reading its socket instead).
    fn take(&self, bytes: &[u8], taker: Taker) -> Taken {
        let (taken, outcome) = {
            let mut engine = self.engine();
            let before = (engine.frames_waiting(), engine.unacknowledged());
            if taker == Taker::Edge && before.0 >= DELIVERED_BACKLOG {
                UdpStats::add(&self.stats.dropped, 1);
                return Taken::default();
            }
            let taken = match Datagram::decode(bytes) {
                Err(_) => {
                    UdpStats::add(&self.stats.malformed, 1);
                    Ok(())
                }
                Ok(d) if d.session != engine.session() || d.kind == Kind::Hello => {
                    // A late hello-ack on the client is harmless; anything else names another session.
                    if d.kind != Kind::HelloAck {
                        UdpStats::add(&self.stats.spoofed, 1);
                    }
                    Ok(())
                }
                Ok(d) => engine.on_datagram(&d, Instant::now()),
            };
            if self.reader_gone.load(Ordering::Acquire) {
                while engine.poll_frame().is_some() {}
            }
            let peer_closed = engine.peer_closed();
            let outcome = Taken {
                news: engine.frames_waiting() > before.0
                    || engine.unacknowledged() < before.1
                    || engine.has_output()
                    || peer_closed,
                peer_closed,
                // Read under the engine's lock, under which the keeper sets what it sleeps until (`rearm`). A
                // client's keeper took the datagram itself and looks again before it sleeps.
                sooner: taker != Taker::Keeper
                    && lock(&self.armed).is_some_and(|armed| engine.deadline() < armed),
            };
            (taken, outcome)
        };
        if let Err(why) = taken {
            self.fail(why);
        }
        outcome
    }
}

/// The reader's wait on a client's socket; dropped, it hands the socket back to the keeper.
pub(super) struct Listening<'a> {
    session: &'a Session,
}

impl Drop for Listening<'_> {
    fn drop(&mut self) {
        self.session.listening.store(false, Ordering::Release);
        self.session.keeper.notify_one();
    }
}

/// What one datagram taken into the engine asks of the session's tasks.
#[derive(Debug, Default, Clone, Copy)]
struct Taken {
    /// A half has something to do now: frames to read, acknowledgements that freed the window, a goodbye, or
    /// something to send.
    news: bool,
    /// The peer said goodbye: the keeper ends too.
    peer_closed: bool,
    /// The engine's next deadline moved before the one the keeper sleeps until.
    sooner: bool,
}

impl Taken {
    /// What two datagrams ask, together.
    fn and(self, other: Taken) -> Taken {
        Taken {
            news: self.news || other.news,
            peer_closed: self.peer_closed || other.peer_closed,
            sooner: self.sooner || other.sooner,
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The hub's demultiplexer's handle on a session: datagrams in, and the end of the session when the edge drops it.
#[derive(Debug, Clone)]
pub struct Inbox {
    pub(super) session: Arc<Session>,
}

impl Inbox {
    /// Puts in a datagram of this session (its id and source address checked by the caller) and wakes the reader
    /// when there is something to do; the datagram is dropped and counted when the reader has fallen
    /// [`DELIVERED_BACKLOG`] frames behind.
    pub fn push(&self, bytes: &[u8]) {
        self.session.wake_for(self.session.take(bytes, Taker::Edge));
    }

    /// Ends the session: the edge no longer routes its datagrams (a new session from the same address replaced it).
    pub fn end(&self) {
        self.session
            .fail("the hub's UDP edge ended the session".to_string());
    }
}
