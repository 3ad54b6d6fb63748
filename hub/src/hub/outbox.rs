//! A connection's outgoing queue: a control lane that is never dropped from and
//! one drop-oldest data lane per subscribed channel.
//!
//! Overflow policy (documented in docs/protocol.md):
//! - Data: each (connection, channel) lane holds at most `lane_msgs` messages
//!   and `lane_bytes` bytes; a new message evicts the oldest and the drop is
//!   counted. The publisher never waits, and one slow subscriber only loses its
//!   own old data.
//! - Control (replies, channel events, service requests): never dropped. A
//!   connection whose control lane exceeds `control_msgs` is not reading at all;
//!   it is closed ("control queue overflow") instead of growing without bound.
//!
//! The writer drains control first, then the data lanes round-robin, so a busy
//! video channel cannot starve an audio channel on the same connection.
//!
//! A removed channel's lane is not thrown away: what a subscriber has queued
//! was published before the removal, so it is still sent, and the removal
//! event follows the lane's last message ([`Outbox::push_after_lane`]). A
//! publisher that sends its last messages and disconnects loses none of them.

use std::collections::{HashMap, VecDeque};
use std::sync::Mutex;

use flow::protocol::{ChanId, Event};
use tokio::sync::Notify;

/// Queue limits for one connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutboxLimits {
    pub lane_msgs: usize,
    pub lane_bytes: usize,
    pub control_msgs: usize,
}

/// Outgoing events of one connection.
#[derive(Debug)]
pub struct Outbox {
    inner: Mutex<Inner>,
    /// Wakes the single writer (a stored permit covers a wake before it waits).
    notify: Notify,
    /// Wakes everyone waiting for the close.
    closing: Notify,
    limits: OutboxLimits,
}

#[derive(Debug, Default)]
struct Inner {
    control: VecDeque<Event>,
    lanes: HashMap<ChanId, Lane>,
    /// Lanes with data, in round-robin order; each id appears at most once.
    ready: VecDeque<ChanId>,
    closed: Option<String>,
}

#[derive(Debug, Default)]
struct Lane {
    queue: VecDeque<(Event, usize)>,
    bytes: usize,
    /// The channel is gone: this event goes out right after the last queued
    /// message, and the lane with it.
    then: Option<Event>,
}

/// Why an outbox closes itself when its control queue is full.
const OVERFLOW: &str = "control queue overflow: the peer is not reading";

/// What `push_data` did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pushed {
    pub dropped: usize,
}

fn lock(m: &Mutex<Inner>) -> std::sync::MutexGuard<'_, Inner> {
    // Every mutation leaves the queues consistent, so a poisoned lock is still usable.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Outbox {
    pub fn new(limits: OutboxLimits) -> Self {
        Outbox {
            inner: Mutex::new(Inner::default()),
            notify: Notify::new(),
            closing: Notify::new(),
            limits,
        }
    }

    /// Queues a control event. Returns false (and closes the outbox) on overflow.
    pub fn push_control(&self, event: Event) -> bool {
        let ok = {
            let mut inner = lock(&self.inner);
            if inner.closed.is_some() {
                return false;
            }
            if inner.control.len() >= self.limits.control_msgs {
                inner.closed = Some(OVERFLOW.into());
                self.closing.notify_waiters();
                false
            } else {
                inner.control.push_back(event);
                true
            }
        };
        self.notify.notify_one();
        ok
    }

    /// Queues a data event of `len` payload bytes on `chan`'s lane, evicting old ones.
    pub fn push_data(&self, chan: ChanId, event: Event, len: usize) -> Pushed {
        let mut dropped = 0;
        {
            let mut inner = lock(&self.inner);
            if inner.closed.is_some() {
                return Pushed { dropped: 0 };
            }
            let Inner {
                lanes,
                ready,
                control,
                ..
            } = &mut *inner;
            let lane = lanes.entry(chan).or_default();
            // A lane still draining a removed channel cannot take a new
            // channel's data (an id is reused only after 32768 others, so
            // this is next to impossible): the old tail goes, its removal
            // event first, as before lanes were drained.
            if let Some(then) = lane.then.take() {
                lane.queue.clear();
                lane.bytes = 0;
                ready.retain(|c| *c != chan);
                control.push_back(then);
            }
            let was_empty = lane.queue.is_empty();
            lane.queue.push_back((event, len));
            lane.bytes += len;
            // Keep at least the newest message even if it alone exceeds the byte cap.
            while lane.queue.len() > 1
                && (lane.queue.len() > self.limits.lane_msgs || lane.bytes > self.limits.lane_bytes)
            {
                if let Some((_, n)) = lane.queue.pop_front() {
                    lane.bytes -= n;
                    dropped += 1;
                }
            }
            if was_empty {
                ready.push_back(chan);
            }
        }
        self.notify.notify_one();
        Pushed { dropped }
    }

    /// Forgets a lane's queued data (after unsubscribe or channel removal).
    pub fn drop_lane(&self, chan: ChanId) {
        let mut inner = lock(&self.inner);
        inner.lanes.remove(&chan);
        inner.ready.retain(|c| *c != chan);
    }

    /// Queues `event` (a channel's removal) behind the messages still queued on
    /// `chan`'s lane, or as a control event if the lane is empty. Returns false
    /// (and closes the outbox) on control overflow, as [`Outbox::push_control`].
    pub fn push_after_lane(&self, chan: ChanId, event: Event) -> bool {
        {
            let mut inner = lock(&self.inner);
            if inner.closed.is_some() {
                return false;
            }
            if let Some(lane) = inner.lanes.get_mut(&chan)
                && !lane.queue.is_empty()
            {
                lane.then = Some(event);
                return true;
            }
            inner.lanes.remove(&chan);
        }
        self.push_control(event)
    }

    /// Moves queued events into `out`: all control events, then data round-robin
    /// until about `max_bytes` of payload are taken.
    pub fn pop_batch(&self, out: &mut Vec<Event>, max_bytes: usize) {
        let mut inner = lock(&self.inner);
        out.extend(inner.control.drain(..));
        let mut taken = 0;
        while taken < max_bytes {
            let Some(chan) = inner.ready.pop_front() else {
                break;
            };
            let Some(lane) = inner.lanes.get_mut(&chan) else {
                continue;
            };
            let Some((event, len)) = lane.queue.pop_front() else {
                continue;
            };
            lane.bytes -= len;
            taken += len + 32;
            let more = !lane.queue.is_empty();
            out.push(event);
            if more {
                inner.ready.push_back(chan);
            } else if let Some(then) = lane.then.take() {
                out.push(then);
                inner.lanes.remove(&chan);
            }
        }
    }

    /// Waits until there is something to send or the outbox is closed.
    pub async fn ready(&self) {
        loop {
            {
                let inner = lock(&self.inner);
                if !inner.control.is_empty() || !inner.ready.is_empty() || inner.closed.is_some() {
                    return;
                }
            }
            self.notify.notified().await;
        }
    }

    /// Marks the outbox closed; the writer sends what is queued, then stops.
    pub fn close(&self, reason: impl Into<String>) {
        {
            let mut inner = lock(&self.inner);
            if inner.closed.is_none() {
                inner.closed = Some(reason.into());
            }
        }
        self.notify.notify_one();
        self.closing.notify_waiters();
    }

    /// Waits until the outbox is closed.
    pub async fn wait_closed(&self) {
        loop {
            let notified = self.closing.notified();
            tokio::pin!(notified);
            // Register before checking, so a close in between is not missed.
            notified.as_mut().enable();
            if self.closed().is_some() {
                return;
            }
            notified.await;
        }
    }

    /// Whether the outbox closed itself because the peer stopped reading (a
    /// fault of the peer, unlike a close by the hub or the connection).
    pub fn overflowed(&self) -> bool {
        lock(&self.inner).closed.as_deref() == Some(OVERFLOW)
    }

    /// Why the outbox was closed, if it was.
    pub fn closed(&self) -> Option<String> {
        lock(&self.inner).closed.clone()
    }

    /// Whether everything queued has been taken.
    pub fn is_drained(&self) -> bool {
        let inner = lock(&self.inner);
        inner.control.is_empty() && inner.ready.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytes::Bytes;

    fn data(chan: ChanId, seq: u64) -> Event {
        Event::Data {
            chan,
            seq,
            ts_us: 0,
            payload: Bytes::from_static(b"x"),
        }
    }

    #[test]
    fn lanes_drop_oldest_and_round_robin() {
        let ob = Outbox::new(OutboxLimits {
            lane_msgs: 2,
            lane_bytes: 1000,
            control_msgs: 4,
        });
        for seq in 1..=3 {
            ob.push_data(1, data(1, seq), 1);
        }
        ob.push_data(2, data(2, 1), 1);
        ob.push_control(Event::StartPublishing { id: 9 });
        let mut out = Vec::new();
        ob.pop_batch(&mut out, 1 << 20);
        let seqs: Vec<_> = out
            .iter()
            .map(|e| match e {
                Event::Data { chan, seq, .. } => (*chan, *seq),
                _ => (-1, 0),
            })
            .collect();
        // Control first; lane 1 lost seq 1; lanes alternate.
        assert_eq!(seqs, vec![(-1, 0), (1, 2), (2, 1), (1, 3)]);
    }

    #[test]
    fn a_removed_channels_queued_data_goes_out_before_its_removal() {
        let ob = Outbox::new(OutboxLimits {
            lane_msgs: 8,
            lane_bytes: 1000,
            control_msgs: 8,
        });
        for seq in 1..=3 {
            ob.push_data(1, data(1, seq), 1);
        }
        ob.push_data(2, data(2, 1), 1);
        assert!(ob.push_after_lane(1, Event::StopPublishing { id: 1 }));
        // An empty lane: the event goes out at once, as a control event.
        assert!(ob.push_after_lane(3, Event::StopPublishing { id: 3 }));
        let mut out = Vec::new();
        ob.pop_batch(&mut out, 1 << 20);
        let seen: Vec<_> = out
            .iter()
            .map(|e| match e {
                Event::Data { chan, seq, .. } => (*chan, *seq),
                Event::StopPublishing { id } => (*id, 0),
                _ => (-1, 0),
            })
            .collect();
        assert_eq!(seen, vec![(3, 0), (1, 1), (2, 1), (1, 2), (1, 3), (1, 0)]);
        assert!(ob.is_drained());
        // The lane is gone with its removal: new data on the id starts afresh.
        ob.push_data(1, data(1, 9), 1);
        out.clear();
        ob.pop_batch(&mut out, 1 << 20);
        assert_eq!(out.len(), 1);
    }

    #[test]
    fn control_overflow_closes() {
        let ob = Outbox::new(OutboxLimits {
            lane_msgs: 2,
            lane_bytes: 1000,
            control_msgs: 1,
        });
        assert!(ob.push_control(Event::StartPublishing { id: 1 }));
        assert!(!ob.push_control(Event::StartPublishing { id: 1 }));
        assert!(ob.closed().is_some());
    }
}
