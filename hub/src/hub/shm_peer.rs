//! One connection's side of shared memory: whether it takes messages by reference, the slots it holds (the writer,
//! `net/shm_writer.rs`, sends them; the session hears them given back), and its release ring.
//!
//! Overflow: a subscriber holds at most `hub.shm_held` slots at once. Past that it gets messages as bytes, written
//! from the segment, until it gives slots back: its writer never waits on it, so a subscriber that keeps messages
//! (a ring of recent frames) costs copies, not a stall. A stalled subscriber stops reading its socket like any
//! other, and its queue drops the oldest, counted; the publisher never waits. A subscriber that dies gives
//! everything back: its held slots are dropped with the connection.
//!
//! Slots come back two ways: in a `Release` frame, or through the release ring (`flow::shm::ring`), which the hub
//! reads whenever its writer sends this connection a message by reference, when the writer goes idle holding slots,
//! and when the subscriber rings (an empty `Release`). Either way a slot is freed only if these books say the
//! connection holds it.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use bytes::Bytes;
use flow::protocol::SlotRef;
use flow::shm::ring::{Overrun, RingReader};

use super::segments::ShmStats;

/// Shared memory as one connection has it; the session and the writer share it.
#[derive(Debug)]
pub struct ShmPeer {
    accepted: AtomicBool,
    books: Mutex<Books>,
    max_held: usize,
    stats: Arc<ShmStats>,
}

#[derive(Debug, Default)]
struct Books {
    /// Slots sent by reference and not given back yet, with the message that holds each.
    held: HashMap<(u32, u32), Bytes>,
    ring: Option<RingReader>,
    /// The writer waits for work: the ring is armed while it holds slots.
    writer_idle: bool,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Books {
    /// Takes what the ring holds into `freed`.
    fn take_ring(&mut self, freed: &mut Vec<Bytes>) -> Result<u64, Overrun> {
        let Books { held, ring, .. } = self;
        let Some(ring) = ring else { return Ok(0) };
        let mut taken = 0;
        ring.take(|segment, slot| {
            if let Some(payload) = held.remove(&(segment, slot)) {
                freed.push(payload);
                taken += 1;
            }
        })?;
        Ok(taken)
    }

    /// Takes what the ring holds; then, while the writer is idle and slots are out, asks the subscriber to ring for
    /// its next release and takes once more (what came before the bell was set).
    fn look(&mut self, freed: &mut Vec<Bytes>) -> Result<u64, Overrun> {
        let taken = self.take_ring(freed)?;
        let waiting = self.writer_idle && !self.held.is_empty();
        match &self.ring {
            Some(ring) if waiting => ring.arm(),
            Some(ring) => {
                ring.disarm();
                return Ok(taken);
            }
            None => return Ok(taken),
        }
        Ok(taken + self.take_ring(freed)?)
    }
}

impl ShmPeer {
    pub fn new(max_held: usize, stats: Arc<ShmStats>) -> Self {
        ShmPeer {
            accepted: AtomicBool::new(false),
            books: Mutex::new(Books::default()),
            max_held: max_held.max(1),
            stats,
        }
    }

    /// The client said `ShmAccept`: large messages go to it by reference from now on.
    pub fn accept(&self) {
        self.accepted.store(true, Ordering::Release);
    }

    pub fn accepted(&self) -> bool {
        self.accepted.load(Ordering::Acquire)
    }

    /// The ring the writer sent this connection.
    pub fn set_ring(&self, ring: RingReader) {
        lock(&self.books).ring = Some(ring);
    }

    /// The client gave these slots back in a `Release` frame (unknown ones are ignored: a late release after a
    /// reconnect), and the ring is read: an empty frame is the subscriber ringing.
    pub fn release(&self, slots: &[SlotRef]) -> Result<(), Overrun> {
        let mut freed = Vec::new();
        let mut books = lock(&self.books);
        freed.extend(
            slots
                .iter()
                .filter_map(|s| books.held.remove(&(s.segment, s.slot))),
        );
        let by_frame = freed.len() as u64;
        let by_ring = books.look(&mut freed);
        self.settle(books, freed, by_frame, by_ring).map(|_| ())
    }

    /// Reads the ring and says how many slots the connection holds now: what the writer asks before it sends a
    /// message by reference.
    pub fn reclaim(&self) -> Result<usize, Overrun> {
        let mut freed = Vec::new();
        let mut books = lock(&self.books);
        let by_ring = books.take_ring(&mut freed);
        self.settle(books, freed, 0, by_ring)
    }

    /// The writer has nothing to send: from now on the subscriber rings for a release while slots are out.
    pub fn writer_idle(&self) -> Result<(), Overrun> {
        let mut freed = Vec::new();
        let mut books = lock(&self.books);
        books.writer_idle = true;
        let by_ring = books.look(&mut freed);
        self.settle(books, freed, 0, by_ring).map(|_| ())
    }

    /// Counts what came back, lets the books go, then frees the slots (which may free their segment) outside the
    /// lock; the slots held after it.
    fn settle(
        &self,
        books: MutexGuard<'_, Books>,
        freed: Vec<Bytes>,
        by_frame: u64,
        by_ring: Result<u64, Overrun>,
    ) -> Result<usize, Overrun> {
        let held = books.held.len();
        drop(books);
        self.stats
            .count_released(by_frame, *by_ring.as_ref().unwrap_or(&0));
        drop(freed);
        by_ring.map(|_| held)
    }

    /// The writer has work again: it reads the ring itself before each message by reference.
    pub fn writer_busy(&self) {
        let mut books = lock(&self.books);
        books.writer_idle = false;
        if let Some(ring) = &books.ring {
            ring.disarm();
        }
    }

    /// Gives back everything the connection held: it is gone.
    pub fn clear(&self) {
        let all = std::mem::take(&mut lock(&self.books).held);
        drop(all);
    }

    /// Slots held now.
    pub fn held(&self) -> usize {
        lock(&self.books).held.len()
    }

    /// The most slots it may hold at once (`hub.shm_held`).
    pub fn max_held(&self) -> usize {
        self.max_held
    }

    /// Records a slot sent to the client, with the message that holds it.
    pub fn hold(&self, slot: SlotRef, payload: Bytes) {
        lock(&self.books)
            .held
            .insert((slot.segment, slot.slot), payload);
    }
}
