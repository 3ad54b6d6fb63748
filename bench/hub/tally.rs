//! What the subscribers of one run received: counts, sequence gaps, latency
//! samples, and the progress the publisher's flow-control window waits on.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use tokio::sync::Notify;

use crate::stamp;

/// Shared by the publisher and every subscriber task of one run.
#[derive(Debug)]
pub struct Tally {
    subs: Vec<SubTally>,
    /// Latency samples are kept only while this is set (the measurement window).
    recording: AtomicBool,
    /// Set while the publisher waits for the window to open, so that
    /// subscribers only pay for a wake-up when someone is waiting.
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
    /// Messages at or below the highest already seen (reordered or duplicated).
    out_of_order: AtomicU64,
    /// Payloads without a readable stamp.
    corrupt: AtomicU64,
    /// The subscription ended (the server disconnected it).
    ended: AtomicBool,
    latencies_ns: Mutex<Vec<u64>>,
}

/// Totals over all subscribers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Totals {
    pub received: u64,
    pub lost: u64,
    pub out_of_order: u64,
    pub corrupt: u64,
    pub ended: u64,
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

    /// Accounts one payload received by subscriber `sub`.
    pub fn record(&self, sub: usize, payload: &[u8]) {
        let now = stamp::clock_ns();
        let Some(s) = self.subs.get(sub) else { return };
        let Some((seq, sent)) = stamp::read(payload) else {
            s.corrupt.fetch_add(1, Ordering::Relaxed);
            return;
        };
        s.received.fetch_add(1, Ordering::Relaxed);
        // Only this subscriber's task writes `highest`, so load-then-store is race free.
        let highest = s.highest.load(Ordering::Relaxed);
        if seq > highest {
            s.lost.fetch_add(seq - highest - 1, Ordering::Relaxed);
            s.highest.store(seq, Ordering::SeqCst);
        } else {
            s.out_of_order.fetch_add(1, Ordering::Relaxed);
        }
        if self.recording.load(Ordering::Relaxed) {
            lock(&s.latencies_ns).push(now.saturating_sub(sent));
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

    /// Whether fewer than `window` of the `sent` messages are on their way.
    pub fn window_open(&self, sent: u64, window: u64) -> bool {
        sent.saturating_sub(self.slowest()) < window
    }

    /// Waits until fewer than `window` of the `sent` messages are still on
    /// their way to the slowest subscriber. Returns false if nothing moved for
    /// `stall` (the system under test stopped delivering).
    pub async fn wait_window(&self, sent: u64, window: u64, stall: Duration) -> bool {
        loop {
            if self.window_open(sent, window) {
                return true;
            }
            let notified = self.progress.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            self.waiting.store(true, Ordering::SeqCst);
            // Check again after announcing the wait, so a receive in between is not missed.
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
            t.out_of_order += s.out_of_order.load(Ordering::Relaxed);
            t.corrupt += s.corrupt.load(Ordering::Relaxed);
            t.ended += u64::from(s.ended.load(Ordering::Relaxed));
        }
        t
    }

    /// Messages a subscriber never got out of the `sent` ones, summed over
    /// subscribers: gaps plus whatever was still missing at the end.
    pub fn missing(&self, sent: u64) -> u64 {
        self.subs
            .iter()
            .map(|s| sent.saturating_sub(s.received.load(Ordering::Relaxed)))
            .sum()
    }

    /// All latency samples recorded so far, in nanoseconds, sorted.
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

    #[tokio::test]
    async fn counts_gaps_and_opens_the_window() {
        let t = Tally::new(2);
        t.set_recording(true);
        for seq in [1, 2, 4] {
            t.record(0, &stamp::stamped(&[0; 32], seq));
        }
        t.record(0, &stamp::stamped(&[0; 32], 3));
        t.record(1, &stamp::stamped(&[0; 32], 1));
        t.record(1, &[1, 2]);
        let totals = t.totals();
        assert_eq!(totals.received, 5);
        assert_eq!(totals.lost, 1);
        assert_eq!(totals.out_of_order, 1);
        assert_eq!(totals.corrupt, 1);
        assert_eq!(t.latencies().len(), 5);
        assert_eq!(t.missing(4), 3);
        // Subscriber 1 is at 1: with 4 sent, a window of 3 is full, 4 is open.
        assert!(t.wait_window(4, 4, Duration::from_millis(10)).await);
        assert!(!t.wait_window(4, 3, Duration::from_millis(10)).await);
        t.end(1);
        assert!(t.wait_window(4, 3, Duration::from_millis(10)).await);
    }
}
