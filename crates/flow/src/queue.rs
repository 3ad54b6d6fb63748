//! A bounded single-consumer queue that drops its oldest item when full.
//!
//! Real-time data loses value with age: when a consumer falls behind, the
//! freshest sample is worth more than the backlog, and the producer must never
//! wait for the consumer. Both the hub (per subscriber and channel) and the SDK
//! (per subscription) use this policy and count what they drop.

use std::collections::VecDeque;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use tokio::sync::Notify;

/// Bounded drop-oldest queue with an async receive side.
#[derive(Debug)]
pub struct DropOldest<T> {
    inner: Mutex<Inner<T>>,
    notify: Notify,
    capacity: usize,
    dropped: AtomicU64,
}

#[derive(Debug)]
struct Inner<T> {
    items: VecDeque<T>,
    closed: bool,
}

impl<T> DropOldest<T> {
    /// A queue holding at most `capacity` items (at least one).
    pub fn new(capacity: usize) -> Self {
        DropOldest {
            inner: Mutex::new(Inner {
                items: VecDeque::new(),
                closed: false,
            }),
            notify: Notify::new(),
            capacity: capacity.max(1),
            dropped: AtomicU64::new(0),
        }
    }

    /// Adds an item, evicting the oldest when full. Returns whether one was dropped.
    /// Items pushed after `close` are discarded silently (nobody will read them).
    pub fn push(&self, item: T) -> bool {
        let dropped = {
            let mut inner = lock(&self.inner);
            if inner.closed {
                return false;
            }
            let dropped = if inner.items.len() >= self.capacity {
                inner.items.pop_front();
                true
            } else {
                false
            };
            inner.items.push_back(item);
            dropped
        };
        if dropped {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
        // A stored permit wakes the single consumer even if it is not waiting yet.
        self.notify.notify_one();
        dropped
    }

    /// Takes the oldest item without waiting.
    pub fn try_pop(&self) -> Option<T> {
        lock(&self.inner).items.pop_front()
    }

    /// Takes the newest item and discards the older ones, returning how many were skipped.
    pub fn pop_latest(&self) -> Option<(T, usize)> {
        let mut inner = lock(&self.inner);
        let newest = inner.items.pop_back()?;
        let skipped = inner.items.len();
        inner.items.clear();
        Some((newest, skipped))
    }

    /// Waits for an item; `None` once the queue is closed and empty.
    pub async fn pop(&self) -> Option<T> {
        loop {
            {
                let mut inner = lock(&self.inner);
                if let Some(item) = inner.items.pop_front() {
                    return Some(item);
                }
                if inner.closed {
                    return None;
                }
            }
            self.notify.notified().await;
        }
    }

    /// Waits until at least one item is queued or the queue is closed.
    pub async fn wait(&self) -> bool {
        loop {
            {
                let inner = lock(&self.inner);
                if !inner.items.is_empty() {
                    return true;
                }
                if inner.closed {
                    return false;
                }
            }
            self.notify.notified().await;
        }
    }

    /// Wakes the consumer for good: `pop` drains what is left, then returns `None`.
    pub fn close(&self) {
        lock(&self.inner).closed = true;
        self.notify.notify_one();
    }

    pub fn len(&self) -> usize {
        lock(&self.inner).items.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Items evicted so far.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// Locks a mutex, recovering the data if a panicking thread poisoned it: the
/// queue's invariants hold after every statement, so the data is still sound.
pub(crate) fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn drops_oldest_and_counts() {
        let q = DropOldest::new(2);
        assert!(!q.push(1));
        assert!(!q.push(2));
        assert!(q.push(3));
        assert_eq!(q.dropped(), 1);
        assert_eq!(q.pop().await, Some(2));
        assert_eq!(q.pop().await, Some(3));
        q.close();
        assert_eq!(q.pop().await, None);
    }

    #[test]
    fn latest_skips_stale() {
        let q = DropOldest::new(8);
        for i in 0..5 {
            q.push(i);
        }
        assert_eq!(q.pop_latest(), Some((4, 4)));
        assert!(q.is_empty());
    }
}
