//! The table of connections that have not logged in yet (`hub.max_unauthenticated`, per door): FlowProtocol
//! connections on every transport and HTTP connections that have not shown a credential. A full table never turns
//! the newcomer away (a stranger who holds places must not keep a client with a token out): it evicts the oldest
//! stranger of the address that holds the most places, and an address at `hub.max_unauthenticated_per_address`
//! gives up its own oldest place. The Unix socket, loopback and remote addresses have tables of their own, so that
//! strangers from the network never evict a local satellite. Evictions and refusals are logged once per address
//! per interval (`Notices`), not once per connection.

use std::collections::{BTreeMap, HashMap};
use std::net::IpAddr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};
use std::time::{Duration, Instant};

use tokio::sync::Notify;

/// How often one address's evictions, refusals and missed deadlines are logged at most.
pub const NOTICE_INTERVAL: Duration = Duration::from_secs(10);
/// A table more than this full (in eighths) shortens the login deadline of newcomers.
const PRESSURE_EIGHTHS: usize = 4;

/// Which table a connection waits in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Door {
    /// The Unix socket: reachable only by local users the socket's permissions let in.
    Unix,
    /// A loopback address.
    Loopback,
    /// Any other address.
    Remote,
}

impl Door {
    /// The door of a network peer.
    pub fn of(ip: IpAddr) -> Door {
        let ip = match ip {
            IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(ip, IpAddr::V4),
            v4 => v4,
        };
        if ip.is_loopback() {
            Door::Loopback
        } else {
            Door::Remote
        }
    }
}

/// Where a stranger comes from: its door and, on the network, its address.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Origin {
    pub door: Door,
    pub ip: Option<IpAddr>,
}

impl Origin {
    pub fn unix() -> Origin {
        Origin {
            door: Door::Unix,
            ip: None,
        }
    }

    pub fn ip(ip: IpAddr) -> Origin {
        Origin {
            door: Door::of(ip),
            ip: Some(ip),
        }
    }

    /// How the logs name it.
    pub fn label(&self) -> String {
        match self.ip {
            Some(ip) => ip.to_string(),
            None => "the unix socket".into(),
        }
    }
}

/// One waiting connection in the table.
#[derive(Debug)]
struct Entry {
    origin: Origin,
    evict: Arc<Evict>,
}

/// The signal that tells a stranger it was evicted, and why: set once, seen by every waiter.
#[derive(Debug, Default)]
struct Evict {
    notify: Notify,
    why: OnceLock<Eviction>,
}

impl Evict {
    fn fire(&self, why: Eviction) {
        let _ = self.why.set(why);
        self.notify.notify_waiters();
    }

    async fn wait(&self) -> Eviction {
        loop {
            let notified = self.notify.notified();
            tokio::pin!(notified);
            // Registered before the check, so a `fire` between the two is not missed.
            notified.as_mut().enable();
            if let Some(why) = self.why.get() {
                return *why;
            }
            notified.await;
        }
    }
}

/// A second view of a stranger's eviction, for a task that does not hold the place itself (an HTTP connection
/// whose place a request may hand over).
#[derive(Debug, Clone)]
pub struct EvictionWatch(Arc<Evict>);

impl EvictionWatch {
    /// Resolves once the stranger was evicted; never if it logged in first.
    pub async fn evicted(&self) -> Eviction {
        self.0.wait().await
    }
}

/// Every stranger, oldest first (ids grow).
#[derive(Debug, Default)]
struct Table {
    next: u64,
    entries: BTreeMap<u64, Entry>,
    per_origin: HashMap<Origin, usize>,
    per_door: HashMap<Door, usize>,
}

impl Table {
    fn remove(&mut self, id: u64) -> Option<Entry> {
        let entry = self.entries.remove(&id)?;
        if let Some(n) = self.per_origin.get_mut(&entry.origin) {
            *n -= 1;
            if *n == 0 {
                self.per_origin.remove(&entry.origin);
            }
        }
        if let Some(n) = self.per_door.get_mut(&entry.origin.door) {
            *n = n.saturating_sub(1);
        }
        Some(entry)
    }

    /// The oldest stranger from `origin`.
    fn oldest_of(&self, origin: Origin) -> Option<u64> {
        self.entries
            .iter()
            .find(|(_, e)| e.origin == origin)
            .map(|(id, _)| *id)
    }

    /// The oldest stranger of the origin behind `door` that holds the most places.
    fn oldest_of_most_crowded(&self, door: Door) -> Option<u64> {
        let crowded = self
            .per_origin
            .iter()
            .filter(|(o, _)| o.door == door)
            .max_by_key(|(o, n)| (**n, std::cmp::Reverse(**o)))
            .map(|(o, _)| *o)?;
        self.oldest_of(crowded)
    }
}

/// Why a stranger was closed before it logged in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Eviction {
    /// Its address held `max_unauthenticated_per_address` places and a newer connection from it came.
    AddressFull,
    /// Its door's table was full and its address held the most places.
    TableFull,
}

impl std::fmt::Display for Eviction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Eviction::AddressFull => {
                "closed before login: its address holds the most connections waiting to log in \
                 (hub.max_unauthenticated_per_address)"
            }
            Eviction::TableFull => {
                "closed before login: the connections waiting to log in are at hub.max_unauthenticated, \
                 and its address holds the most of them"
            }
        })
    }
}

/// The table of strangers and its caps.
#[derive(Debug)]
pub struct Admission {
    table: Mutex<Table>,
    /// Places per door.
    cap: usize,
    /// Places per address.
    per_address: usize,
    evictions: AtomicUsize,
    notices: Notices,
}

impl Admission {
    /// `cap` places per door, `per_address` per address (both at least 1).
    pub fn new(cap: usize, per_address: usize) -> Self {
        Admission {
            table: Mutex::new(Table::default()),
            cap: cap.max(1),
            per_address: per_address.max(1),
            evictions: AtomicUsize::new(0),
            notices: Notices::new(NOTICE_INTERVAL),
        }
    }

    fn lock(&self) -> MutexGuard<'_, Table> {
        self.table.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Takes a place for a connection from `origin`, evicting another stranger when its address or its door is full.
    pub fn admit(self: &Arc<Self>, origin: Origin) -> Stranger {
        let mut table = self.lock();
        let from_origin = table.per_origin.get(&origin).copied().unwrap_or(0);
        // Every local process shares the loopback address and the socket: the cap per address is for the network.
        let victim = if origin.door == Door::Remote && from_origin >= self.per_address {
            table
                .oldest_of(origin)
                .map(|id| (id, Eviction::AddressFull))
        } else if table.per_door.get(&origin.door).copied().unwrap_or(0) >= self.cap {
            table
                .oldest_of_most_crowded(origin.door)
                .map(|id| (id, Eviction::TableFull))
        } else {
            None
        };
        if let Some((id, why)) = victim
            && let Some(entry) = table.remove(id)
        {
            self.evictions.fetch_add(1, Ordering::Relaxed);
            entry.evict.fire(why);
            self.notices.note(&entry.origin, "eviction", || {
                format!("{why} (from {})", entry.origin.label())
            });
        }
        let id = table.next;
        table.next += 1;
        let evict = Arc::new(Evict::default());
        table.entries.insert(
            id,
            Entry {
                origin,
                evict: evict.clone(),
            },
        );
        *table.per_origin.entry(origin).or_default() += 1;
        let in_door = table.per_door.entry(origin.door).or_default();
        *in_door += 1;
        let pressed = *in_door * 8 > self.cap * PRESSURE_EIGHTHS;
        Stranger {
            place: Some((self.clone(), id)),
            evict,
            origin,
            pressed,
        }
    }

    /// Connections waiting to log in now, all doors together.
    pub fn waiting(&self) -> usize {
        self.lock().entries.len()
    }

    /// Strangers closed to make room since the start.
    pub fn evictions(&self) -> usize {
        self.evictions.load(Ordering::Relaxed)
    }

    /// The rate limiter for messages about strangers, per address.
    pub fn notices(&self) -> &Notices {
        &self.notices
    }

    fn release(&self, id: u64) {
        self.lock().remove(id);
    }
}

/// One place among the strangers, given back on login, on close, or taken by an eviction.
#[derive(Debug)]
pub struct Stranger {
    place: Option<(Arc<Admission>, u64)>,
    evict: Arc<Evict>,
    origin: Origin,
    pressed: bool,
}

impl Stranger {
    /// No place taken: the server's own modules are never capped.
    pub fn trusted() -> Self {
        Stranger {
            place: None,
            evict: Arc::new(Evict::default()),
            origin: Origin::unix(),
            pressed: false,
        }
    }

    /// The connection logged in (or showed a credential): its place is free for another stranger.
    pub fn logged_in(&mut self) {
        if let Some((admission, id)) = self.place.take() {
            admission.release(id);
        }
    }

    /// Whether it still waits in the table.
    pub fn is_waiting(&self) -> bool {
        self.place.is_some()
    }

    /// Resolves once the table has evicted this stranger to make room for a newer one; never after login.
    pub async fn evicted(&self) -> Eviction {
        self.evict.wait().await
    }

    /// A view of the eviction signal that outlives a hand-over of the place.
    pub fn watch(&self) -> EvictionWatch {
        EvictionWatch(self.evict.clone())
    }

    /// Where it comes from.
    pub fn origin(&self) -> Origin {
        self.origin
    }

    /// The login deadline: `base`, or at most `pressed` while the table was filling up when it came.
    pub fn login_deadline(&self, base: Duration, pressed: Duration) -> Duration {
        if self.pressed {
            base.min(pressed)
        } else {
            base
        }
    }
}

impl Drop for Stranger {
    fn drop(&mut self) {
        self.logged_in();
    }
}

/// Logs a message about an address at most once per interval, with the count of those left out meanwhile.
#[derive(Debug)]
pub struct Notices {
    interval: Duration,
    seen: Mutex<HashMap<NoticeKey, (Instant, u64)>>,
}

/// What a notice is about: an address and the kind of message (evictions and missed deadlines apart).
type NoticeKey = (Origin, &'static str);

/// Addresses remembered at most; beyond, the memory starts over (a flood from many addresses logs a few more).
const NOTICES_KEPT: usize = 4096;

impl Notices {
    pub fn new(interval: Duration) -> Self {
        Notices {
            interval,
            seen: Mutex::new(HashMap::new()),
        }
    }

    /// Logs `message()` at WARN unless a message of this `kind` about `origin` was logged within the interval.
    pub fn note(&self, origin: &Origin, kind: &'static str, message: impl FnOnce() -> String) {
        let now = Instant::now();
        let mut seen = self.seen.lock().unwrap_or_else(PoisonError::into_inner);
        if seen.len() >= NOTICES_KEPT {
            seen.clear();
        }
        match seen.get_mut(&(*origin, kind)) {
            Some((last, quiet)) if now.duration_since(*last) < self.interval => {
                *quiet += 1;
            }
            Some((last, quiet)) => {
                let left_out = std::mem::take(quiet);
                *last = now;
                drop(seen);
                tracing::warn!(
                    "{} ({left_out} more like it from this address in the last {} s)",
                    message(),
                    self.interval.as_secs()
                );
            }
            None => {
                seen.insert((*origin, kind), (now, 0));
                drop(seen);
                tracing::warn!("{}", message());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn remote(last: u8) -> Origin {
        Origin::ip(IpAddr::from([192, 0, 2, last]))
    }

    #[test]
    fn places_are_given_back_on_login_and_on_drop() {
        let a = Arc::new(Admission::new(2, 2));
        let mut one = a.admit(remote(1));
        let two = a.admit(remote(1));
        assert_eq!(a.waiting(), 2);
        one.logged_in();
        assert_eq!(a.waiting(), 1);
        one.logged_in();
        assert_eq!(a.waiting(), 1, "a place is given back once");
        drop(two);
        assert_eq!(a.waiting(), 0);
    }

    #[tokio::test]
    async fn a_full_address_gives_up_its_own_oldest_place() {
        let a = Arc::new(Admission::new(10, 2));
        let first = a.admit(remote(1));
        let _second = a.admit(remote(1));
        let other = a.admit(remote(2));
        let _third = a.admit(remote(1));
        tokio::time::timeout(Duration::from_secs(1), first.evicted())
            .await
            .expect("the oldest of the full address is evicted");
        assert!(
            tokio::time::timeout(Duration::from_millis(50), other.evicted())
                .await
                .is_err(),
            "another address keeps its place"
        );
        assert_eq!(a.waiting(), 3);
        assert_eq!(a.evictions(), 1);
    }

    #[tokio::test]
    async fn a_full_table_evicts_from_the_most_crowded_address_not_the_newcomer() {
        let a = Arc::new(Admission::new(4, 8));
        let flood: Vec<Stranger> = (0..3).map(|_| a.admit(remote(1))).collect();
        let lone = a.admit(remote(2));
        // The table is full: the newcomer gets in and the flood's oldest goes.
        let newcomer = a.admit(remote(3));
        assert!(newcomer.is_waiting());
        tokio::time::timeout(Duration::from_secs(1), flood[0].evicted())
            .await
            .expect("the flood's oldest is evicted");
        assert!(
            tokio::time::timeout(Duration::from_millis(50), lone.evicted())
                .await
                .is_err(),
            "the lone stranger keeps its place"
        );
        assert_eq!(a.waiting(), 4);
    }

    #[tokio::test]
    async fn doors_have_tables_of_their_own() {
        let a = Arc::new(Admission::new(2, 8));
        let local = a.admit(Origin::ip(IpAddr::from([127, 0, 0, 1])));
        let unix = a.admit(Origin::unix());
        let _flood: Vec<Stranger> = (0..20).map(|i| a.admit(remote(i))).collect();
        for kept in [&local, &unix] {
            assert!(
                tokio::time::timeout(Duration::from_millis(50), kept.evicted())
                    .await
                    .is_err(),
                "remote strangers never evict a local one"
            );
        }
        assert_eq!(a.waiting(), 4);
    }

    #[test]
    fn a_filling_table_shortens_the_login_deadline() {
        let a = Arc::new(Admission::new(4, 8));
        let base = Duration::from_secs(5);
        let short = Duration::from_secs(1);
        let early = a.admit(remote(1));
        let _b = a.admit(remote(2));
        let late = a.admit(remote(3));
        assert_eq!(early.login_deadline(base, short), base);
        assert_eq!(late.login_deadline(base, short), short);
    }

    #[test]
    fn an_ipv4_mapped_loopback_address_is_loopback() {
        let mapped: IpAddr = "::ffff:127.0.0.1".parse().expect("address");
        assert_eq!(Door::of(mapped), Door::Loopback);
        assert_eq!(Door::of("10.0.0.1".parse().expect("address")), Door::Remote);
    }
}
