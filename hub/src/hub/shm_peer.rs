//! One connection's side of shared memory: whether it takes messages by reference, and the slots it holds (the
//! writer, `net/shm_writer.rs`, sends them; the session hears them given back).
//!
//! Overflow: a subscriber holds at most `hub.shm_held` slots at once. Past that it gets messages as bytes, written
//! from the segment, until it gives slots back: its writer never waits on it, so a subscriber that keeps messages
//! (a ring of recent frames) costs copies, not a stall. A stalled subscriber stops reading its socket like any
//! other, and its queue drops the oldest, counted; the publisher never waits. A subscriber that dies gives
//! everything back: its held slots are dropped with the connection.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard};

use bytes::Bytes;
use flow::protocol::SlotRef;

/// Shared memory as one connection has it; the session and the writer share it.
#[derive(Debug)]
pub struct ShmPeer {
    accepted: AtomicBool,
    /// Slots sent by reference and not given back yet, with the message that holds each.
    held: Mutex<HashMap<(u32, u32), Bytes>>,
    max_held: usize,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl ShmPeer {
    pub fn new(max_held: usize) -> Self {
        ShmPeer {
            accepted: AtomicBool::new(false),
            held: Mutex::new(HashMap::new()),
            max_held: max_held.max(1),
        }
    }

    /// The client said `ShmAccept`: large messages go to it by reference from now on.
    pub fn accept(&self) {
        self.accepted.store(true, Ordering::Release);
    }

    pub fn accepted(&self) -> bool {
        self.accepted.load(Ordering::Acquire)
    }

    /// The client gave these slots back (unknown ones are ignored: a late release after a reconnect).
    pub fn release(&self, slots: &[SlotRef]) {
        let mut held = lock(&self.held);
        let freed: Vec<Bytes> = slots
            .iter()
            .filter_map(|s| held.remove(&(s.segment, s.slot)))
            .collect();
        drop(held);
        // The slots free (and may free their segment) here, outside the lock.
        drop(freed);
    }

    /// Gives back everything the connection held: it is gone.
    pub fn clear(&self) {
        let all = std::mem::take(&mut *lock(&self.held));
        drop(all);
    }

    /// Slots held now.
    pub fn held(&self) -> usize {
        lock(&self.held).len()
    }

    /// The most slots it may hold at once (`hub.shm_held`).
    pub fn max_held(&self) -> usize {
        self.max_held
    }

    /// Records a slot sent to the client, with the message that holds it.
    pub fn hold(&self, slot: SlotRef, payload: Bytes) {
        lock(&self.held).insert((slot.segment, slot.slot), payload);
    }
}
