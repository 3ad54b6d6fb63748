//! What the subscribers of one cell received: counts, sequence gaps, latency samples, and the progress the
//! publisher's window waits on. Subscribers are tokio tasks (hub and raw-TCP modes) or threads (iceoryx2); both
//! record here, and the publisher waits on it from async code.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use tokio::sync::Notify;

use crate::stamp;

/// Shared by the publisher and every subscriber of one cell.
#[derive(Debug)]
pub struct Tally {
    subs: Vec<SubTally>,
    /// Latency samples are kept only while this is set.
    recording: AtomicBool,
    /// Set while the publisher waits for its window to open, so that subscribers pay for a wake-up only then.
    waiting: AtomicBool,
    progress: Notify,
}

#[derive(Debug, Default)]
struct SubTally {
    /// Highest sequence number seen (sequences start at 1).
    highest: AtomicU64,
    received: AtomicU64,
    /// Messages skipped over: a jump in the sequence.
    lost: AtomicU64,
    /// Payloads without a readable stamp, or at or below the highest sequence seen.
    damaged: AtomicU64,
    /// The sum of the last bytes read: the touch of the payload's far end, kept so that it is really made.
    last_bytes: AtomicU64,
    ended: AtomicBool,
    latencies_ns: Mutex<Vec<u64>>,
}

/// Totals over all subscribers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Totals {
    pub received: u64,
    pub lost: u64,
    pub damaged: u64,
    pub ended: u64,
    pub last_bytes: u64,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Tally {
    pub fn new(subscribers: usize) -> Self {
        Tally {
            subs: (0..subscribers).map(|_| SubTally::default()).collect(),
            recording: AtomicBool::new(false),
            waiting: AtomicBool::new(false),
            progress: Notify::new(),
        }
    }

    pub fn subscribers(&self) -> usize {
        self.subs.len()
    }

    /// Accounts one payload received by subscriber `sub`, touching its stamp and its last byte only.
    pub fn record(&self, sub: usize, payload: &[u8]) {
        let now = stamp::clock_ns();
        let Some(s) = self.subs.get(sub) else { return };
        let Some(t) = stamp::touch(payload) else {
            s.damaged.fetch_add(1, Ordering::Relaxed);
            return;
        };
        s.received.fetch_add(1, Ordering::Relaxed);
        s.last_bytes.fetch_add(u64::from(t.last), Ordering::Relaxed);
        // Only this subscriber writes `highest`, so load-then-store is race free.
        let highest = s.highest.load(Ordering::Relaxed);
        if t.seq > highest {
            s.lost.fetch_add(t.seq - highest - 1, Ordering::Relaxed);
            s.highest.store(t.seq, Ordering::SeqCst);
        } else {
            s.damaged.fetch_add(1, Ordering::Relaxed);
        }
        if self.recording.load(Ordering::Relaxed) {
            lock(&s.latencies_ns).push(now.saturating_sub(t.sent_ns));
        }
        if self.waiting.load(Ordering::SeqCst) {
            self.progress.notify_one();
        }
    }

    /// Marks subscriber `sub` as gone, so the window stops waiting for it.
    pub fn end(&self, sub: usize) {
        if let Some(s) = self.subs.get(sub) {
            s.ended.store(true, Ordering::SeqCst);
        }
        self.progress.notify_one();
    }

    /// The lowest sequence every live subscriber has reached; `u64::MAX` when none is live.
    fn slowest(&self) -> u64 {
        self.subs
            .iter()
            .filter(|s| !s.ended.load(Ordering::SeqCst))
            .map(|s| s.highest.load(Ordering::SeqCst))
            .min()
            .unwrap_or(u64::MAX)
    }

    /// Whether fewer than `window` of the `sent` messages are on their way to the slowest subscriber.
    pub fn window_open(&self, sent: u64, window: u64) -> bool {
        sent.saturating_sub(self.slowest()) < window
    }

    /// Waits until the window is open again. False if nothing moved for `stall` (the mode stopped delivering).
    pub async fn wait_window(&self, sent: u64, window: u64, stall: Duration) -> bool {
        loop {
            if self.window_open(sent, window) {
                return true;
            }
            let notified = self.progress.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            self.waiting.store(true, Ordering::SeqCst);
            // Look again after announcing the wait, so that a delivery in between is not missed.
            if self.window_open(sent, window) {
                self.waiting.store(false, Ordering::SeqCst);
                return true;
            }
            let woke = tokio::time::timeout(stall, notified).await.is_ok();
            self.waiting.store(false, Ordering::SeqCst);
            if !woke {
                return false;
            }
        }
    }

    pub fn set_recording(&self, on: bool) {
        self.recording.store(on, Ordering::SeqCst);
    }

    pub fn totals(&self) -> Totals {
        let mut t = Totals::default();
        for s in &self.subs {
            t.received += s.received.load(Ordering::Relaxed);
            t.lost += s.lost.load(Ordering::Relaxed);
            t.damaged += s.damaged.load(Ordering::Relaxed);
            t.ended += u64::from(s.ended.load(Ordering::Relaxed));
            t.last_bytes = t
                .last_bytes
                .wrapping_add(s.last_bytes.load(Ordering::Relaxed));
        }
        t
    }

    /// All latency samples so far, in nanoseconds, sorted.
    pub fn latencies(&self) -> Vec<u64> {
        let mut all: Vec<u64> = self
            .subs
            .iter()
            .flat_map(|s| lock(&s.latencies_ns).clone())
            .collect();
        all.sort_unstable();
        all
    }
}

impl agent_bench::raw_tcp::Receiver for Tally {
    fn record(&self, sub: usize, payload: &[u8]) {
        Tally::record(self, sub, payload);
    }

    fn end(&self, sub: usize) {
        Tally::end(self, sub);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stamped(seq: u64) -> Vec<u8> {
        let mut p = vec![1u8; 32];
        stamp::write(&mut p, seq);
        p
    }

    #[tokio::test]
    async fn counts_gaps_and_opens_the_window() {
        let t = Tally::new(2);
        t.set_recording(true);
        for seq in [1, 2, 4] {
            t.record(0, &stamped(seq));
        }
        t.record(0, &stamped(3));
        t.record(1, &stamped(1));
        t.record(1, &[1, 2]);
        let totals = t.totals();
        assert_eq!(totals.received, 5);
        assert_eq!(totals.lost, 1);
        assert_eq!(totals.damaged, 2);
        assert_eq!(totals.last_bytes, 5);
        assert_eq!(t.latencies().len(), 5);
        // Subscriber 1 is at 1: with 4 sent, a window of 3 is full, 4 is open.
        assert!(t.wait_window(4, 4, Duration::from_millis(10)).await);
        assert!(!t.wait_window(4, 3, Duration::from_millis(10)).await);
        t.end(1);
        assert!(t.wait_window(4, 3, Duration::from_millis(10)).await);
    }
}
