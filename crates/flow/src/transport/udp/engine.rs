//! One end of a FlowProtocol UDP session as a state machine without I/O: whole frames in, datagrams out, and the
//! other way round. Time is passed in, so that the session (`session.rs`) and the tests decide when it moves.
//!
//! Frames travel on two lanes, chosen by opcode (byte 4 of the frame):
//!
//! - **best effort**: `Publish` (client -> hub) and `Data` (hub -> client). Each frame gets a message number and
//!   goes out once, cut into fragments of at most `mtu` bytes. The receiver puts a frame together only when every
//!   fragment came, and delivers it at once; a frame with a missing fragment is dropped after
//!   [`Settings::reassembly_timeout`] (or sooner when the reassembly memory is full, or when 64 newer frames have
//!   begun) and counted in [`UdpStats::lost`], never delivered damaged. Duplicates are dropped by message number.
//!   A frame of several fragments that stops coming together is asked for again: after [`Settings::nack_delay`]
//!   without a new fragment the receiver sends a `nack` naming the missing ones, up to [`Settings::nacks`] times,
//!   and the sender sends them again from the few frames it keeps ([`Settings::resend_bytes`]). A 52 kB picture
//!   is 44 fragments: at 5% loss only 10% of pictures would otherwise arrive whole. A frame of one fragment is
//!   not asked for (a lost audio packet is better skipped than late).
//! - **reliable**: every other frame. Each fragment gets a sequence number and is kept until acknowledged, sent
//!   again after `rto_min` doubling up to `rto_max`; with no acknowledgement for `give_up` the session fails. The
//!   receiver delivers fragments in sequence order exactly once (duplicates are dropped by sequence number) and
//!   answers with a cumulative acknowledgement and a bitmap of the 32 sequence numbers after it.
//!
//! Until the hub sees its own successful reply to a `Login`, its end holds an amplification budget: it sends at
//! most as many bytes as it received, and takes reliable messages of at most [`Settings::pre_login_max`] bytes.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use bytes::Bytes;
use tokio::time::Instant;

use super::datagram::{Datagram, HEADER, Kind, MAX_DATAGRAM};
use crate::protocol::message::op;

/// The tunables of a session. The defaults suit a LAN or the Internet at a 1280-byte IPv6 minimum MTU.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Frame bytes per datagram (the header's 16 bytes come on top); at most `MAX_DATAGRAM - HEADER` (1456).
    pub mtu: usize,
    pub rto_min: Duration,
    pub rto_max: Duration,
    /// A reliable datagram unacknowledged this long fails the session.
    pub give_up: Duration,
    /// Reliable datagrams in flight at once; more wait.
    pub window: usize,
    /// Out-of-order reliable bytes the receiver keeps; beyond that a datagram is dropped (and sent again).
    pub receive_bytes: usize,
    /// How long a best-effort frame may wait for its missing fragments.
    pub reassembly_timeout: Duration,
    /// Bytes of incomplete best-effort frames kept at once; the oldest is dropped (and counted) to make room.
    pub reassembly_bytes: usize,
    /// The largest frame taken (as the frame reader's maximum, checked here before it is put together).
    pub max_message: usize,
    /// The largest reliable frame and the out-of-order bytes kept before login (the hub's end only).
    pub pre_login_max: usize,
    /// Nothing heard for this long ends the session.
    pub idle_timeout: Duration,
    /// A keepalive goes out after this long without sending.
    pub keepalive: Duration,
    /// An incomplete best-effort frame with no new fragment for this long asks for the missing ones (`nack`).
    pub nack_delay: Duration,
    /// How many times one frame's missing fragments are asked for.
    pub nacks: u8,
    /// Bytes of recent best-effort frames of several fragments the sender keeps to answer `nack`s.
    pub resend_bytes: usize,
}

/// The default frame bytes per datagram.
pub const DEFAULT_MTU: usize = 1200;

impl Default for Settings {
    fn default() -> Self {
        Settings {
            mtu: DEFAULT_MTU,
            rto_min: Duration::from_millis(50),
            rto_max: Duration::from_secs(1),
            give_up: Duration::from_secs(10),
            window: 256,
            receive_bytes: 1 << 20,
            reassembly_timeout: Duration::from_secs(1),
            reassembly_bytes: 4 << 20,
            max_message: 16 << 20,
            pre_login_max: 16 * 1024,
            idle_timeout: Duration::from_secs(15),
            keepalive: Duration::from_secs(3),
            nack_delay: Duration::from_millis(10),
            nacks: 3,
            resend_bytes: 1 << 20,
        }
    }
}

/// What a UDP endpoint (the hub's edge, a client's link) has counted, shared with whoever reports it.
#[derive(Debug, Default)]
pub struct UdpStats {
    /// Datagrams that did not decode.
    pub malformed: AtomicU64,
    /// Well-formed datagrams for no session, or for a session from another address.
    pub spoofed: AtomicU64,
    /// Datagrams dropped for want of room (a full session queue, the session cap, the receive window).
    pub dropped: AtomicU64,
    /// Best-effort frames lost (a fragment missing) and dropped whole.
    pub lost: AtomicU64,
    /// Reliable datagrams sent again, and best-effort fragments sent again on a `nack`.
    pub retransmitted: AtomicU64,
    /// `nack`s sent for best-effort frames missing fragments.
    pub nacks: AtomicU64,
    /// Duplicate datagrams discarded.
    pub duplicates: AtomicU64,
    /// Sessions open now (the hub's edge).
    pub sessions: AtomicU64,
    /// Datagrams sent (every session's, retransmissions included).
    pub sent: AtomicU64,
    /// System calls that sent them (a segmented send or a `sendmmsg` takes a burst at once: `batch.rs`).
    pub send_calls: AtomicU64,
    /// Datagrams received from the socket (the hub's edge, a client's link).
    pub received: AtomicU64,
    /// System calls that received them (`recvmmsg`, with the kernel's coalescing: `batch.rs`).
    pub receive_calls: AtomicU64,
}

impl UdpStats {
    pub fn get(counter: &AtomicU64) -> u64 {
        counter.load(Ordering::Relaxed)
    }

    pub fn add(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Ordering::Relaxed);
    }
}

/// Whether a frame goes on the best-effort lane.
pub fn best_effort(frame: &[u8]) -> bool {
    matches!(frame.get(4), Some(&op::PUBLISH) | Some(&op::DATA))
}

/// `a < b` in sequence space (wrapping).
fn before(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) < 0
}

#[derive(Debug)]
struct InFlight {
    datagram: Bytes,
    first_sent: Instant,
    sent_at: Instant,
    rto: Duration,
}

#[derive(Debug)]
struct Received {
    frag: u16,
    frags: u16,
    payload: Bytes,
}

#[derive(Debug)]
struct Partial {
    frags: u16,
    got: BTreeMap<u16, Bytes>,
    bytes: usize,
    began: Instant,
    /// When the last fragment (or the last `nack`) came: the next `nack` is due `nack_delay` after it.
    progress: Instant,
    nacked: u8,
}

/// A best-effort frame of several fragments the sender keeps to answer `nack`s.
#[derive(Debug)]
struct Kept {
    message: u32,
    fragments: Vec<Bytes>,
    bytes: usize,
    answered: u8,
}

/// The best-effort receiver's window: bit `i` of each map is message number `top - i`.
#[derive(Debug)]
struct Window {
    top: u32,
    begun: u64,
    done: u64,
}

/// Why a session failed.
pub type Failure = String;

/// One end of a session.
#[derive(Debug)]
pub struct Engine {
    settings: Settings,
    session: u32,
    stats: Arc<UdpStats>,
    // Sending.
    next_seq: u32,
    in_flight: BTreeMap<u32, InFlight>,
    waiting: VecDeque<(u32, Bytes)>,
    next_message: u32,
    out: VecDeque<Bytes>,
    kept: VecDeque<Kept>,
    kept_bytes: usize,
    ack_due: bool,
    last_sent: Instant,
    // Receiving.
    rcv_next: u32,
    rcv_buf: BTreeMap<u32, Received>,
    rcv_bytes: usize,
    assembling: Vec<u8>,
    assembling_next: u16,
    window: Window,
    partials: HashMap<u32, Partial>,
    partial_bytes: usize,
    delivered: VecDeque<Bytes>,
    last_heard: Instant,
    peer_closed: bool,
    /// The hub's end before login: bytes it may still send, and the request id of the `Login` it delivered.
    guard: Option<(usize, Option<u32>)>,
}

impl Engine {
    /// A client's end of `session`.
    pub fn client(session: u32, settings: Settings, stats: Arc<UdpStats>, now: Instant) -> Self {
        Self::new(session, settings, stats, now, None)
    }

    /// The hub's end of `session`, which may send `budget` bytes before it hears more (what the hello brought,
    /// less the hello-ack).
    pub fn hub(
        session: u32,
        settings: Settings,
        stats: Arc<UdpStats>,
        now: Instant,
        budget: usize,
    ) -> Self {
        Self::new(session, settings, stats, now, Some((budget, None)))
    }

    fn new(
        session: u32,
        settings: Settings,
        stats: Arc<UdpStats>,
        now: Instant,
        guard: Option<(usize, Option<u32>)>,
    ) -> Self {
        let mut settings = settings;
        settings.mtu = settings.mtu.clamp(1, MAX_DATAGRAM - HEADER);
        Engine {
            settings,
            session,
            stats,
            next_seq: 0,
            in_flight: BTreeMap::new(),
            waiting: VecDeque::new(),
            next_message: 0,
            out: VecDeque::new(),
            kept: VecDeque::new(),
            kept_bytes: 0,
            ack_due: false,
            last_sent: now,
            rcv_next: 0,
            rcv_buf: BTreeMap::new(),
            rcv_bytes: 0,
            assembling: Vec::new(),
            assembling_next: 0,
            // Message numbers start at 0: everything "before" it counts as done, so nothing is counted lost.
            window: Window {
                top: u32::MAX,
                begun: u64::MAX,
                done: u64::MAX,
            },
            partials: HashMap::new(),
            partial_bytes: 0,
            delivered: VecDeque::new(),
            last_heard: now,
            peer_closed: false,
            guard,
        }
    }

    pub fn session(&self) -> u32 {
        self.session
    }

    /// Whether the hub's end still waits for a login.
    pub fn before_login(&self) -> bool {
        self.guard.is_some()
    }

    /// Queues `data` (whole frames) for sending.
    pub fn send_frames(&mut self, data: &[u8]) -> Result<(), Failure> {
        let mut rest = data;
        while !rest.is_empty() {
            let len = rest
                .get(..4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize + 4)
                .unwrap_or(rest.len())
                .min(rest.len());
            let (frame, tail) = rest.split_at(len);
            rest = tail;
            self.send_frame(frame)?;
        }
        Ok(())
    }

    fn send_frame(&mut self, frame: &[u8]) -> Result<(), Failure> {
        let mtu = self.settings.mtu;
        let frags = u16::try_from(frame.len().div_ceil(mtu))
            .map_err(|_| format!("a frame of {} bytes is too large for UDP", frame.len()))?;
        if let Some((_, Some(req))) = self.guard
            && frame.get(4) == Some(&op::REPLY)
            && frame.get(5..9) == Some(&req.to_le_bytes()[..])
            && frame.get(9).is_some_and(|&tag| tag != 0xff)
        {
            // The login succeeded: the peer is known now.
            self.guard = None;
        }
        let best = best_effort(frame);
        let message = self.next_message;
        if best {
            self.next_message = message.wrapping_add(1);
        }
        let mut kept = (best && frags > 1).then(|| Kept {
            message,
            fragments: Vec::with_capacity(frags as usize),
            bytes: 0,
            answered: 0,
        });
        for (i, chunk) in frame.chunks(mtu).enumerate() {
            let kind = if best {
                Kind::BestEffort
            } else {
                Kind::Reliable
            };
            let seq = if best { message } else { self.next_seq };
            let d = Datagram {
                kind,
                session: self.session,
                seq,
                frag: i as u16,
                frags,
                payload: chunk,
            };
            let bytes = Bytes::from(d.to_vec());
            if best {
                if let Some(k) = &mut kept {
                    k.bytes += bytes.len();
                    k.fragments.push(bytes.clone());
                }
                self.out.push_back(bytes);
            } else {
                self.waiting.push_back((seq, bytes));
                self.next_seq = seq.wrapping_add(1);
            }
        }
        if let Some(k) = kept {
            self.keep(k);
        }
        Ok(())
    }

    /// Keeps a best-effort frame for `nack`s: the newest frames within `resend_bytes`, and no more than the
    /// receiver's window of 64 frames could still ask for.
    fn keep(&mut self, k: Kept) {
        self.kept_bytes += k.bytes;
        self.kept.push_back(k);
        while self.kept_bytes > self.settings.resend_bytes || self.kept.len() > 64 {
            let Some(old) = self.kept.pop_front() else {
                break;
            };
            self.kept_bytes -= old.bytes;
        }
    }

    /// The peer lacks fragments of best-effort frame `message`: sends them again, if the frame is still kept and
    /// has not been asked for too often (a peer cannot make us send a frame more than `nacks` times over).
    fn on_nack(&mut self, d: &Datagram<'_>) {
        let limit = self.settings.nacks;
        let Some(k) = self.kept.iter_mut().find(|k| k.message == d.seq) else {
            return;
        };
        if k.answered >= limit {
            return;
        }
        k.answered += 1;
        let mut again = 0;
        for (i, fragment) in k.fragments.iter().enumerate() {
            if d.payload
                .get(i / 8)
                .is_some_and(|b| b & (1 << (i % 8)) != 0)
            {
                self.out.push_back(fragment.clone());
                again += 1;
            }
        }
        UdpStats::add(&self.stats.retransmitted, again);
    }

    /// Whether the sender can take more frames now (its reliable backlog is within a window).
    pub fn can_take(&self) -> bool {
        self.waiting.len() < self.settings.window
    }

    /// Whether every reliable datagram was acknowledged.
    pub fn all_acknowledged(&self) -> bool {
        self.waiting.is_empty() && self.in_flight.is_empty()
    }

    /// The next datagram to send now, if any (and the budget before login allows it).
    pub fn poll_send(&mut self, now: Instant) -> Option<Bytes> {
        while self.in_flight.len() < self.settings.window
            && let Some((seq, d)) = self.waiting.pop_front()
        {
            self.in_flight.insert(
                seq,
                InFlight {
                    datagram: d.clone(),
                    first_sent: now,
                    sent_at: now,
                    rto: self.settings.rto_min,
                },
            );
            self.out.push_back(d);
        }
        if self.ack_due {
            self.ack_due = false;
            let mut bits = 0u32;
            for i in 0..32 {
                if self
                    .rcv_buf
                    .contains_key(&self.rcv_next.wrapping_add(1 + i))
                {
                    bits |= 1 << i;
                }
            }
            let d = Datagram {
                kind: Kind::Ack,
                session: self.session,
                seq: self.rcv_next,
                frag: 0,
                frags: 0,
                payload: &bits.to_le_bytes(),
            };
            self.out.push_front(Bytes::from(d.to_vec()));
        }
        let next = self.out.front()?;
        if let Some((budget, _)) = &mut self.guard {
            if next.len() > *budget {
                return None;
            }
            *budget -= next.len();
        }
        self.last_sent = now;
        self.out.pop_front()
    }

    /// A close datagram, to send as the last one.
    pub fn close_datagram(&self) -> Vec<u8> {
        Datagram::bare(Kind::Close, self.session, 0).to_vec()
    }

    /// The next frame received, in order for the reliable lane.
    pub fn poll_frame(&mut self) -> Option<Bytes> {
        self.delivered.pop_front()
    }

    /// Frames received and not yet taken.
    pub fn frames_waiting(&self) -> usize {
        self.delivered.len()
    }

    /// Reliable datagrams not yet acknowledged, sent or waiting to be.
    pub fn unacknowledged(&self) -> usize {
        self.in_flight.len() + self.waiting.len()
    }

    /// Whether something waits to be sent now (an acknowledgement, fragments asked for again).
    pub fn has_output(&self) -> bool {
        self.ack_due || !self.out.is_empty()
    }

    /// Whether the peer said goodbye.
    pub fn peer_closed(&self) -> bool {
        self.peer_closed
    }

    /// Takes in a datagram of this session (its session id and source already checked by the caller); `len` is
    /// its size on the wire.
    pub fn on_datagram(&mut self, d: &Datagram<'_>, now: Instant) -> Result<(), Failure> {
        self.last_heard = now;
        if let Some((budget, _)) = &mut self.guard {
            *budget = budget.saturating_add(HEADER + d.payload.len());
        }
        match d.kind {
            Kind::Reliable => self.on_reliable(d),
            Kind::BestEffort => {
                self.on_best_effort(d, now);
                Ok(())
            }
            Kind::Ack => {
                self.on_ack(d);
                Ok(())
            }
            Kind::Close => {
                self.peer_closed = true;
                Ok(())
            }
            Kind::Nack => {
                // Before login there is nothing best effort to ask for.
                if self.guard.is_none() {
                    self.on_nack(d);
                }
                Ok(())
            }
            Kind::Keepalive | Kind::Hello | Kind::HelloAck => Ok(()),
        }
    }

    fn on_ack(&mut self, d: &Datagram<'_>) {
        let Ok(bits) = <[u8; 4]>::try_from(d.payload).map(u32::from_le_bytes) else {
            return;
        };
        // Only what was sent can be acknowledged: a forged acknowledgement far ahead must not empty the window.
        if before(self.next_seq, d.seq) {
            return;
        }
        let acked: Vec<u32> = self
            .in_flight
            .keys()
            .copied()
            .filter(|&s| {
                before(s, d.seq) || {
                    let i = s.wrapping_sub(d.seq).wrapping_sub(1);
                    i < 32 && bits & (1 << i) != 0
                }
            })
            .collect();
        for s in acked {
            self.in_flight.remove(&s);
        }
    }

    fn message_limit(&self) -> usize {
        if self.guard.is_some() {
            self.settings.pre_login_max
        } else {
            self.settings.max_message
        }
    }

    fn on_reliable(&mut self, d: &Datagram<'_>) -> Result<(), Failure> {
        self.ack_due = true;
        let ahead = d.seq.wrapping_sub(self.rcv_next);
        if before(d.seq, self.rcv_next) || self.rcv_buf.contains_key(&d.seq) {
            UdpStats::add(&self.stats.duplicates, 1);
            return Ok(());
        }
        let room = if self.guard.is_some() {
            self.settings.pre_login_max
        } else {
            self.settings.receive_bytes
        };
        if ahead as usize >= self.settings.window.max(1) * 4
            || (ahead > 0 && self.rcv_bytes + d.payload.len() > room)
        {
            UdpStats::add(&self.stats.dropped, 1);
            return Ok(());
        }
        self.rcv_bytes += d.payload.len();
        self.rcv_buf.insert(
            d.seq,
            Received {
                frag: d.frag,
                frags: d.frags,
                payload: Bytes::copy_from_slice(d.payload),
            },
        );
        while let Some(r) = self.rcv_buf.remove(&self.rcv_next) {
            self.rcv_next = self.rcv_next.wrapping_add(1);
            self.rcv_bytes -= r.payload.len();
            if r.frag != self.assembling_next {
                return Err(format!(
                    "reliable fragment {} of {} where {} was due",
                    r.frag, r.frags, self.assembling_next
                ));
            }
            if r.frag == 0 {
                let most = r.frags as usize * self.settings.mtu.max(r.payload.len());
                if r.frags > 1 && most > self.message_limit() + self.settings.mtu {
                    return Err(format!(
                        "a frame of {} fragments is larger than the {} bytes allowed",
                        r.frags,
                        self.message_limit()
                    ));
                }
            }
            self.assembling.extend_from_slice(&r.payload);
            if self.assembling.len() > self.message_limit() {
                return Err(format!(
                    "a frame larger than the {} bytes allowed",
                    self.message_limit()
                ));
            }
            if r.frag + 1 == r.frags {
                self.assembling_next = 0;
                let frame = Bytes::from(std::mem::take(&mut self.assembling));
                self.note_login(&frame);
                self.delivered.push_back(frame);
            } else {
                self.assembling_next = r.frag + 1;
            }
        }
        Ok(())
    }

    fn note_login(&mut self, frame: &[u8]) {
        if let Some((_, login)) = &mut self.guard
            && frame.get(4) == Some(&op::LOGIN)
            && let Some(req) = frame.get(5..9)
        {
            *login = Some(u32::from_le_bytes([req[0], req[1], req[2], req[3]]));
        }
    }

    /// Moves the best-effort window up to `seq`, counting what falls out of it unfinished.
    fn advance_to(&mut self, seq: u32) {
        let w = &mut self.window;
        let k = seq.wrapping_sub(w.top);
        let (begun, done) = if k >= 64 {
            (0, 0)
        } else {
            (w.begun << k, w.done << k)
        };
        // Bits shifted out: message numbers top-63 .. top-63+k-1 (all of the window when k >= 64).
        let falling = if k >= 64 { u64::MAX } else { !(u64::MAX >> k) };
        let unfinished =
            (!w.done & falling).count_ones() as u64 + if k > 64 { u64::from(k - 64) } else { 0 };
        w.top = seq;
        w.begun = begun;
        w.done = done;
        if unfinished > 0 {
            UdpStats::add(&self.stats.lost, unfinished);
        }
        // Partials that fell out are gone (counted above).
        let top = self.window.top;
        let stale: Vec<u32> = self
            .partials
            .keys()
            .copied()
            .filter(|&m| top.wrapping_sub(m) >= 64)
            .collect();
        for m in stale {
            if let Some(p) = self.partials.remove(&m) {
                self.partial_bytes -= p.bytes;
            }
        }
    }

    fn mark_done(&mut self, message: u32) {
        let i = self.window.top.wrapping_sub(message);
        if i < 64 {
            self.window.done |= 1 << i;
        }
    }

    fn on_best_effort(&mut self, d: &Datagram<'_>, now: Instant) {
        if self.guard.is_some() {
            // Nothing before login is best effort; publishing needs a login.
            UdpStats::add(&self.stats.dropped, 1);
            return;
        }
        if before(self.window.top, d.seq) {
            self.advance_to(d.seq);
        }
        let i = self.window.top.wrapping_sub(d.seq);
        if i >= 64 || self.window.done & (1 << i) != 0 {
            // Too old (already counted lost) or already delivered.
            UdpStats::add(&self.stats.duplicates, 1);
            return;
        }
        self.window.begun |= 1 << i;
        if d.frags == 1 {
            self.window.done |= 1 << i;
            self.delivered.push_back(Bytes::copy_from_slice(d.payload));
            return;
        }
        if d.frags as usize * self.settings.mtu.max(d.payload.len())
            > self.settings.max_message + self.settings.mtu
        {
            self.mark_done(d.seq);
            UdpStats::add(&self.stats.lost, 1);
            return;
        }
        while self.partial_bytes + d.payload.len() > self.settings.reassembly_bytes {
            let Some(oldest) = self
                .partials
                .iter()
                .min_by_key(|(_, p)| p.began)
                .map(|(&m, _)| m)
            else {
                break;
            };
            self.drop_partial(oldest);
        }
        let p = self.partials.entry(d.seq).or_insert_with(|| Partial {
            frags: d.frags,
            got: BTreeMap::new(),
            bytes: 0,
            began: now,
            progress: now,
            nacked: 0,
        });
        if p.frags != d.frags || p.got.contains_key(&d.frag) {
            UdpStats::add(&self.stats.duplicates, 1);
            return;
        }
        p.progress = now;
        p.bytes += d.payload.len();
        self.partial_bytes += d.payload.len();
        p.got.insert(d.frag, Bytes::copy_from_slice(d.payload));
        if p.got.len() == p.frags as usize
            && let Some(p) = self.partials.remove(&d.seq)
        {
            self.partial_bytes -= p.bytes;
            let mut frame = Vec::with_capacity(p.bytes);
            for piece in p.got.values() {
                frame.extend_from_slice(piece);
            }
            self.mark_done(d.seq);
            self.delivered.push_back(Bytes::from(frame));
        }
    }

    fn drop_partial(&mut self, message: u32) {
        if let Some(p) = self.partials.remove(&message) {
            self.partial_bytes -= p.bytes;
            self.mark_done(message);
            UdpStats::add(&self.stats.lost, 1);
        }
    }

    /// When [`Engine::on_timer`] has work next.
    pub fn deadline(&self) -> Instant {
        let mut at = self.last_heard + self.settings.idle_timeout;
        // A keepalive is due only when nothing else waits to go out (which, held by the budget before login, may
        // wait long: that must not wake the keeper over and over).
        if self.out.is_empty() {
            at = at.min(self.last_sent + self.settings.keepalive);
        }
        for f in self.in_flight.values() {
            at = at.min(f.sent_at + f.rto);
        }
        for p in self.partials.values() {
            at = at.min(p.began + self.settings.reassembly_timeout);
            if p.nacked < self.settings.nacks {
                at = at.min(p.progress + self.settings.nack_delay);
            }
        }
        at
    }

    /// Sends again what is due, drops overdue fragments, keeps the link alive; fails an idle or unanswered session.
    pub fn on_timer(&mut self, now: Instant) -> Result<(), Failure> {
        if now >= self.last_heard + self.settings.idle_timeout {
            return Err(format!(
                "nothing heard for {} s",
                self.settings.idle_timeout.as_secs()
            ));
        }
        let mut resend = Vec::new();
        for f in self.in_flight.values_mut() {
            if now < f.sent_at + f.rto {
                continue;
            }
            if now >= f.first_sent + self.settings.give_up {
                return Err(format!(
                    "no acknowledgement for {} s",
                    self.settings.give_up.as_secs()
                ));
            }
            f.sent_at = now;
            f.rto = (f.rto * 2).min(self.settings.rto_max);
            resend.push(f.datagram.clone());
        }
        UdpStats::add(&self.stats.retransmitted, resend.len() as u64);
        self.out.extend(resend);
        let overdue: Vec<u32> = self
            .partials
            .iter()
            .filter(|(_, p)| now >= p.began + self.settings.reassembly_timeout)
            .map(|(&m, _)| m)
            .collect();
        for m in overdue {
            self.drop_partial(m);
        }
        let (nacks, delay) = (self.settings.nacks, self.settings.nack_delay);
        let mut asks = Vec::new();
        for (&m, p) in self.partials.iter_mut() {
            if p.nacked >= nacks || now < p.progress + delay {
                continue;
            }
            p.nacked += 1;
            p.progress = now;
            let mut missing = vec![0u8; (p.frags as usize).div_ceil(8)];
            for i in 0..p.frags {
                if !p.got.contains_key(&i) {
                    missing[i as usize / 8] |= 1 << (i % 8);
                }
            }
            // The bitmap of a frame too large for one nack names its first fragments only; the next nack the rest.
            missing.truncate(self.settings.mtu);
            asks.push(
                Datagram {
                    kind: Kind::Nack,
                    session: self.session,
                    seq: m,
                    frag: 0,
                    frags: 0,
                    payload: &missing,
                }
                .to_vec(),
            );
        }
        UdpStats::add(&self.stats.nacks, asks.len() as u64);
        self.out.extend(asks.into_iter().map(Bytes::from));
        if self.out.is_empty() && now >= self.last_sent + self.settings.keepalive {
            self.out.push_back(Bytes::from(
                Datagram::bare(Kind::Keepalive, self.session, 0).to_vec(),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn frame(op_code: u8, req: u32, body: &[u8]) -> Vec<u8> {
        let mut f = ((body.len() + 5) as u32).to_le_bytes().to_vec();
        f.push(op_code);
        f.extend(req.to_le_bytes());
        f.extend(body);
        f
    }

    fn body(n: usize, seed: u32) -> Vec<u8> {
        (0..n)
            .map(|i| (i as u32).wrapping_mul(131).wrapping_add(seed) as u8)
            .collect()
    }

    fn pair(now: Instant) -> (Engine, Engine, Arc<UdpStats>, Arc<UdpStats>) {
        let (sa, sb) = (Arc::<UdpStats>::default(), Arc::<UdpStats>::default());
        (
            Engine::client(9, Settings::default(), sa.clone(), now),
            Engine::client(9, Settings::default(), sb.clone(), now),
            sa,
            sb,
        )
    }

    /// Moves every datagram `from` sends into `to`, through a network that drops, duplicates and reorders.
    fn carry(from: &mut Engine, to: &mut Engine, now: Instant, rng: &mut impl Rng, loss: f64) {
        let mut wire = Vec::new();
        while let Some(d) = from.poll_send(now) {
            if rng.random_bool(loss) {
                continue;
            }
            if rng.random_bool(loss) {
                wire.push(d.clone());
            }
            wire.push(d);
        }
        for i in (1..wire.len()).rev() {
            if rng.random_bool(0.2) {
                wire.swap(i, rng.random_range(0..=i));
            }
        }
        for d in wire {
            let d = Datagram::decode(&d).expect("own datagrams decode");
            to.on_datagram(&d, now).expect("no failure");
        }
    }

    #[test]
    fn reliable_frames_cross_a_lossy_network_once_each_in_order() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let mut now = Instant::now();
        let (mut a, mut b, sa, sb) = pair(now);
        let frames: Vec<Vec<u8>> = (0..200)
            .map(|i| frame(op::CALL, i, &body(rng.random_range(0..5000), i)))
            .collect();
        for f in &frames {
            a.send_frames(f).expect("send");
        }
        let mut got = Vec::new();
        for _ in 0..2000 {
            carry(&mut a, &mut b, now, &mut rng, 0.1);
            carry(&mut b, &mut a, now, &mut rng, 0.1);
            while let Some(f) = b.poll_frame() {
                got.push(f.to_vec());
            }
            if got.len() == frames.len() && a.all_acknowledged() {
                break;
            }
            now += Duration::from_millis(60);
            a.on_timer(now).expect("alive");
            b.on_timer(now).expect("alive");
        }
        assert_eq!(got, frames);
        assert!(a.all_acknowledged());
        assert!(UdpStats::get(&sa.retransmitted) > 0);
        assert!(UdpStats::get(&sb.duplicates) > 0);
    }

    #[test]
    fn best_effort_frames_arrive_intact_or_are_counted_lost() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut now = Instant::now();
        let (mut a, mut b, _, sb) = pair(now);
        let n = 300u32;
        let mut got = Vec::new();
        for i in 0..n {
            let f = frame(op::PUBLISH, 0, &body(100 + (i as usize * 37) % 4000, i));
            a.send_frames(&f).expect("send");
            carry(&mut a, &mut b, now, &mut rng, 0.05);
            while let Some(f) = b.poll_frame() {
                got.push(f.to_vec());
            }
            now += Duration::from_millis(5);
            b.on_timer(now).expect("alive");
        }
        now += Duration::from_secs(2);
        b.on_timer(now).expect("alive");
        let mut seen = std::collections::HashSet::new();
        for f in &got {
            let len = f.len() - 9;
            let i = (0..n)
                .find(|&i| 100 + (i as usize * 37) % 4000 == len && f[9..] == body(len, i)[..])
                .expect("every delivered frame is one that was sent, intact");
            assert!(seen.insert(i), "frame {i} delivered twice");
        }
        let lost = UdpStats::get(&sb.lost);
        assert!(lost > 0, "5% loss over {n} frames lost none");
        // Every frame is delivered or counted, except those at the very end that no newer frame passed.
        assert!(got.len() as u64 + lost <= u64::from(n));
        assert!(got.len() as u64 + lost + 64 >= u64::from(n));
    }

    #[test]
    fn pictures_missing_fragments_are_asked_for_again_and_arrive_whole_at_5_percent_loss() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let mut now = Instant::now();
        let (mut a, mut b, sa, sb) = pair(now);
        // 15 pictures a second of 52 kB (44 fragments): without asking again, 0.95^44 = 10% would arrive whole.
        let n = 60u32;
        let mut got = Vec::new();
        for i in 0..n {
            a.send_frames(&frame(op::PUBLISH, 0, &body(52_000, i)))
                .expect("send");
            for _ in 0..13 {
                carry(&mut a, &mut b, now, &mut rng, 0.05);
                carry(&mut b, &mut a, now, &mut rng, 0.05);
                while let Some(f) = b.poll_frame() {
                    got.push(f);
                }
                now += Duration::from_millis(5);
                a.on_timer(now).expect("alive");
                b.on_timer(now).expect("alive");
            }
        }
        let mut seen = std::collections::HashSet::new();
        for f in &got {
            let i = (0..n)
                .find(|&i| f[9..] == body(52_000, i)[..])
                .expect("every delivered picture is one that was sent, intact");
            assert!(seen.insert(i), "picture {i} delivered twice");
        }
        assert!(UdpStats::get(&sb.nacks) > 0, "nothing was asked for again");
        assert!(UdpStats::get(&sa.retransmitted) > 0);
        assert!(
            got.len() as f64 >= 0.85 * f64::from(n),
            "{} of {n} pictures arrived whole",
            got.len()
        );
    }

    #[test]
    fn a_nack_is_answered_a_bounded_number_of_times_and_only_for_kept_frames() {
        let now = Instant::now();
        let (mut a, _b, sa, _) = pair(now);
        a.send_frames(&frame(op::PUBLISH, 0, &body(5000, 1)))
            .expect("send");
        while a.poll_send(now).is_some() {}
        let session = a.session();
        let ask = |seq: u32| {
            Datagram {
                kind: Kind::Nack,
                session,
                seq,
                frag: 0,
                frags: 0,
                payload: &[0b0000_0101],
            }
            .to_vec()
        };
        // Frame 0 is kept: fragments 0 and 2 go again, three times over at most.
        for _ in 0..5 {
            let d = ask(0);
            a.on_datagram(&Datagram::decode(&d).expect("decodes"), now)
                .expect("alive");
        }
        let mut again = 0;
        while a.poll_send(now).is_some() {
            again += 1;
        }
        assert_eq!(again, 2 * 3);
        assert_eq!(UdpStats::get(&sa.retransmitted), 6);
        // A frame never sent is not there to send.
        let d = ask(9);
        a.on_datagram(&Datagram::decode(&d).expect("decodes"), now)
            .expect("alive");
        assert!(a.poll_send(now).is_none());
    }

    #[test]
    fn before_login_the_hub_sends_no_more_than_it_heard() {
        let now = Instant::now();
        let stats = Arc::<UdpStats>::default();
        let mut hub = Engine::hub(1, Settings::default(), stats, now, 100);
        // A large reply to a login that never happened stays queued beyond the budget.
        hub.send_frames(&frame(op::REPLY, 1, &body(3000, 1)))
            .expect("queued");
        let mut sent = 0;
        while let Some(d) = hub.poll_send(now) {
            sent += d.len();
        }
        assert!(sent <= 100, "sent {sent}");
        // A login (as a reliable datagram) gives budget and, once answered successfully, lifts the guard.
        let login = frame(op::LOGIN, 7, b"xx");
        let d = Datagram {
            kind: Kind::Reliable,
            session: 1,
            seq: 0,
            frag: 0,
            frags: 1,
            payload: &login,
        };
        hub.on_datagram(&d, now).expect("taken");
        assert_eq!(hub.poll_frame().as_deref(), Some(&login[..]));
        assert!(hub.before_login());
        hub.send_frames(&frame(op::REPLY, 7, &[0])).expect("queued");
        assert!(!hub.before_login());
    }

    #[test]
    fn a_stranger_cannot_send_a_large_frame() {
        let now = Instant::now();
        let mut hub = Engine::hub(1, Settings::default(), Arc::default(), now, 0);
        let d = Datagram {
            kind: Kind::Reliable,
            session: 1,
            seq: 0,
            frag: 0,
            frags: 1000,
            payload: &[0; 1200],
        };
        assert!(hub.on_datagram(&d, now).is_err());
    }

    #[test]
    fn an_unanswered_session_fails_after_give_up() {
        let mut now = Instant::now();
        let (mut a, _, _, _) = pair(now);
        a.send_frames(&frame(op::PING, 1, &[])).expect("send");
        let mut result = Ok(());
        for _ in 0..400 {
            while a.poll_send(now).is_some() {}
            now += Duration::from_millis(50);
            result = a.on_timer(now);
            if result.is_err() {
                break;
            }
        }
        assert!(result.is_err());
    }
}
