//! The release ring: where a shared-memory subscriber puts the slots it is done with, for the hub to take without a
//! frame each way.
//!
//! ```text
//! offset 0     magic:u32 = "FREL" | capacity:u32 | reserved to 64
//! offset 64    head:u32   releases written, wrapping (only the subscriber writes it) | reserved to 128
//! offset 128   tail:u32   releases taken, wrapping (only the hub writes it)         | reserved to 192
//! offset 192   bell:u32   1: the hub is idle with slots out, ring it with a `Release` (only the hub writes it)
//! offset 256   entry * capacity, entry = segment:u32 | slot:u32   (little-endian atomics)
//! ```
//!
//! One ring per subscribing connection, made by the hub, mapped read-write by both (its descriptor travels beside
//! `ReleaseRing`). The subscriber writes entries and then `head`; the hub reads entries up to `head` and then
//! writes `tail`. Each counter sits on its own cache line, so the two sides do not steal each other's.
//!
//! **The hub trusts nothing it reads here.** It keeps its own copy of `tail`, takes a released slot only if its own
//! books say this connection holds it (today's rule for a `Release` frame), and treats a `head` more than
//! `capacity` ahead of its `tail` as a broken protocol. A subscriber that scribbles on the ring can only lose its
//! own releases: its slots then come back when its connection ends, as a killed subscriber's do.
//!
//! **Nothing released is left behind.** The hub takes from the ring whenever its writer sends this connection a
//! message by reference. When the writer goes idle holding slots it sets `bell` and takes once more, and clears
//! `bell` when it has work again. A subscriber that finds `bell` set after writing `head` rings the hub (an empty
//! `Release` frame, on which the hub takes again), unless `bell` is clear when it comes to send it: then the hub
//! woke after the entry was written and its next idle look finds it. Both sides write their word, fence, then read
//! the other's (`SeqCst`), so at least one of them sees the other. The subscriber waits a little before it rings
//! (the SDK's `RING_DELAY`), so that a stream ringing at every message costs no frame at all: the hub wakes for
//! the next message first.

use std::io;
use std::os::fd::{BorrowedFd, OwnedFd};
use std::sync::atomic::{AtomicU32, Ordering, fence};

use super::Mapping;
use super::layout::PAGE;

/// The first word of a ring.
pub const MAGIC: u32 = u32::from_le_bytes(*b"FREL");
const CAPACITY_OFFSET: usize = 4;
const HEAD_OFFSET: usize = 64;
const TAIL_OFFSET: usize = 128;
const BELL_OFFSET: usize = 192;
const ENTRIES_OFFSET: usize = 256;
/// The fewest and the most entries a ring has (a power of two in between).
pub const MIN_CAPACITY: u32 = 64;
pub const MAX_CAPACITY: u32 = 1 << 16;

/// The ring's length for `capacity` entries: whole pages.
pub fn ring_len(capacity: u32) -> usize {
    (ENTRIES_OFFSET + 8 * capacity as usize).div_ceil(PAGE) * PAGE
}

/// The capacity for a subscriber that may hold `held` slots at once: it never has more releases pending than slots
/// held, so a ring of that many never fills for a subscriber that keeps the protocol.
pub fn capacity_for(held: usize) -> u32 {
    let wanted = u32::try_from(held).unwrap_or(MAX_CAPACITY);
    wanted
        .checked_next_power_of_two()
        .unwrap_or(MAX_CAPACITY)
        .clamp(MIN_CAPACITY, MAX_CAPACITY)
}

/// Why a capacity is refused, if it is.
pub fn check_capacity(capacity: u32) -> Result<(), String> {
    if !(MIN_CAPACITY..=MAX_CAPACITY).contains(&capacity) || !capacity.is_power_of_two() {
        return Err(format!(
            "release ring of {capacity} entries (a power of two in {MIN_CAPACITY} ..= {MAX_CAPACITY})"
        ));
    }
    Ok(())
}

/// The words of a mapped ring, checked once.
#[derive(Debug)]
struct Words {
    map: Mapping,
    capacity: u32,
}

impl Words {
    fn new(map: Mapping, capacity: u32) -> io::Result<Words> {
        check_capacity(capacity).map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e))?;
        if map.len() < ring_len(capacity) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!(
                    "release ring of {} bytes, {} expected",
                    map.len(),
                    ring_len(capacity)
                ),
            ));
        }
        Ok(Words { map, capacity })
    }

    fn word(&self, offset: usize) -> &AtomicU32 {
        // Every offset used is inside `ring_len(capacity)`, checked in `new`, and a multiple of 4.
        match self.map.word(offset) {
            Some(word) => word,
            None => unreachable!("offset {offset} checked against the ring's length"),
        }
    }

    fn head(&self) -> &AtomicU32 {
        self.word(HEAD_OFFSET)
    }

    fn tail(&self) -> &AtomicU32 {
        self.word(TAIL_OFFSET)
    }

    fn bell(&self) -> &AtomicU32 {
        self.word(BELL_OFFSET)
    }

    /// The two words of entry `index` (counted from 0, wrapping).
    fn entry(&self, index: u32) -> (&AtomicU32, &AtomicU32) {
        let at = ENTRIES_OFFSET + 8 * (index & (self.capacity - 1)) as usize;
        (self.word(at), self.word(at + 4))
    }
}

/// What a push asks of its caller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pushed {
    /// Written; the hub takes it when it next looks.
    Quiet,
    /// Written, and the hub is idle: send it an empty `Release` frame, unless [`RingWriter::hub_idle`] says it woke
    /// in the meantime.
    Ring,
    /// No room (a subscriber past its `hub.shm_held`, or one that skipped the protocol): give the slot back in a
    /// `Release` frame instead.
    Full,
}

/// The subscriber's side: writes releases. One writer per ring (`&mut self`).
#[derive(Debug)]
pub struct RingWriter {
    words: Words,
    head: u32,
}

impl RingWriter {
    /// Maps the ring the hub sent (its read-write descriptor) for `capacity` entries.
    pub fn open(fd: OwnedFd, capacity: u32) -> io::Result<RingWriter> {
        check_capacity(capacity).map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e))?;
        let map = Mapping::open(fd, ring_len(capacity), true)?;
        let words = Words::new(map, capacity)?;
        let magic = words.word(0).load(Ordering::Relaxed);
        let stated = words.word(CAPACITY_OFFSET).load(Ordering::Relaxed);
        if magic != MAGIC || stated != capacity {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!(
                    "not a release ring of {capacity} entries (magic {magic:#x}, capacity {stated})"
                ),
            ));
        }
        let head = words.head().load(Ordering::Relaxed);
        Ok(RingWriter { words, head })
    }

    /// Puts `slot` of `segment` in the ring.
    pub fn push(&mut self, segment: u32, slot: u32) -> Pushed {
        let tail = self.words.tail().load(Ordering::Acquire);
        if self.head.wrapping_sub(tail) >= self.words.capacity {
            return Pushed::Full;
        }
        let (seg_word, slot_word) = self.words.entry(self.head);
        seg_word.store(segment, Ordering::Relaxed);
        slot_word.store(slot, Ordering::Relaxed);
        self.head = self.head.wrapping_add(1);
        self.words.head().store(self.head, Ordering::Release);
        // Pairs with the hub's fence in `RingReader::arm`: either it sees this head, or this sees its bell.
        fence(Ordering::SeqCst);
        if self.hub_idle() {
            Pushed::Ring
        } else {
            Pushed::Quiet
        }
    }

    /// Whether the hub is idle with slots out, so that only a `Release` frame makes it look. Read again before
    /// ringing: if it reads false after a push that read true, the hub woke since and takes that push at its next
    /// idle look.
    pub fn hub_idle(&self) -> bool {
        self.words.bell().load(Ordering::SeqCst) == 1
    }
}

/// The ring broke its protocol: the subscriber wrote more than it could have.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "the release ring's head is {ahead} entries ahead of what the hub took, past its {capacity} entries"
)]
pub struct Overrun {
    pub ahead: u32,
    pub capacity: u32,
}

/// The hub's side: makes the ring and takes releases. One reader per ring (`&mut self`).
#[derive(Debug)]
pub struct RingReader {
    words: Words,
    /// What the hub took: its own copy, never read back from the shared word.
    tail: u32,
}

impl RingReader {
    /// A new ring of `capacity` entries (see [`capacity_for`]).
    pub fn create(capacity: u32) -> io::Result<RingReader> {
        check_capacity(capacity).map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e))?;
        let map = Mapping::create("flow-release", ring_len(capacity))?;
        let words = Words::new(map, capacity)?;
        words.word(0).store(MAGIC, Ordering::Relaxed);
        words
            .word(CAPACITY_OFFSET)
            .store(capacity, Ordering::Relaxed);
        Ok(RingReader { words, tail: 0 })
    }

    pub fn capacity(&self) -> u32 {
        self.words.capacity
    }

    /// The read-write descriptor the subscriber maps.
    pub fn fd(&self) -> BorrowedFd<'_> {
        self.words.map.fd()
    }

    /// Calls `taken(segment, slot)` for each release written since the last take, in order; how many.
    pub fn take(&mut self, mut taken: impl FnMut(u32, u32)) -> Result<u32, Overrun> {
        let head = self.words.head().load(Ordering::Acquire);
        let ahead = head.wrapping_sub(self.tail);
        if ahead > self.words.capacity {
            return Err(Overrun {
                ahead,
                capacity: self.words.capacity,
            });
        }
        for k in 0..ahead {
            let (seg_word, slot_word) = self.words.entry(self.tail.wrapping_add(k));
            taken(
                seg_word.load(Ordering::Relaxed),
                slot_word.load(Ordering::Relaxed),
            );
        }
        self.tail = head;
        // The entries are read: the subscriber may write over them.
        self.words.tail().store(head, Ordering::Release);
        Ok(ahead)
    }

    /// Asks the subscriber to ring for its releases; the caller takes once more after this.
    pub fn arm(&self) {
        self.words.bell().store(1, Ordering::SeqCst);
        // Pairs with the subscriber's fence in `RingWriter::push`.
        fence(Ordering::SeqCst);
    }

    /// The hub looks on its own again (its writer is busy, or nothing is out): no frame needed. `SeqCst`, so that a
    /// subscriber that reads it clear before ringing knows the hub's next arm (and look) comes after its push.
    pub fn disarm(&self) {
        self.words.bell().store(0, Ordering::SeqCst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::fd::AsFd;

    fn pair(capacity: u32) -> (RingReader, RingWriter) {
        let reader = RingReader::create(capacity).expect("create");
        let fd = reader.fd().try_clone_to_owned().expect("dup");
        let writer = RingWriter::open(fd, capacity).expect("open");
        (reader, writer)
    }

    fn taken(reader: &mut RingReader) -> Vec<(u32, u32)> {
        let mut all = Vec::new();
        reader
            .take(|segment, slot| all.push((segment, slot)))
            .expect("take");
        all
    }

    #[test]
    fn releases_come_out_in_order_across_the_wrap_and_a_full_ring_says_so() {
        let (mut reader, mut writer) = pair(64);
        for round in 0..5u32 {
            for i in 0..40 {
                assert_eq!(writer.push(round, i), Pushed::Quiet);
            }
            let all = taken(&mut reader);
            assert_eq!(all, (0..40).map(|i| (round, i)).collect::<Vec<_>>());
        }
        for i in 0..64 {
            assert_eq!(writer.push(9, i), Pushed::Quiet);
        }
        assert_eq!(writer.push(9, 64), Pushed::Full, "64 entries pending");
        assert_eq!(taken(&mut reader).len(), 64);
        assert_eq!(writer.push(9, 65), Pushed::Quiet, "room again");
    }

    #[test]
    fn counters_that_wrap_past_the_largest_u32_lose_nothing() {
        let mut reader = RingReader::create(64).expect("create");
        let start = u32::MAX - 5;
        reader.words.head().store(start, Ordering::Relaxed);
        reader.words.tail().store(start, Ordering::Relaxed);
        reader.tail = start;
        let fd = reader.fd().try_clone_to_owned().expect("dup");
        let mut writer = RingWriter::open(fd, 64).expect("open");
        for i in 0..20 {
            assert_eq!(writer.push(3, i), Pushed::Quiet);
        }
        assert_eq!(
            taken(&mut reader),
            (0..20).map(|i| (3, i)).collect::<Vec<_>>()
        );
    }

    #[test]
    fn an_armed_ring_asks_to_be_rung_until_the_hub_disarms_it() {
        let (mut reader, mut writer) = pair(64);
        reader.arm();
        assert_eq!(writer.push(1, 1), Pushed::Ring);
        assert_eq!(writer.push(1, 2), Pushed::Ring);
        assert!(writer.hub_idle());
        assert_eq!(taken(&mut reader), vec![(1, 1), (1, 2)]);
        reader.disarm();
        assert!(!writer.hub_idle(), "woke: no frame needed");
        assert_eq!(writer.push(1, 3), Pushed::Quiet);
        assert_eq!(taken(&mut reader), vec![(1, 3)]);
    }

    #[test]
    fn a_head_written_past_the_capacity_is_an_overrun_and_the_hub_keeps_its_own_tail() {
        let (mut reader, mut writer) = pair(64);
        assert_eq!(writer.push(2, 7), Pushed::Quiet);
        // A subscriber that scribbles on the hub's tail gains nothing: the hub reads from its own copy.
        reader.words.tail().store(1000, Ordering::Relaxed);
        assert_eq!(taken(&mut reader), vec![(2, 7)]);
        reader.words.head().store(500, Ordering::Relaxed);
        assert_eq!(
            reader.take(|_, _| {}),
            Err(Overrun {
                ahead: 499,
                capacity: 64
            })
        );
    }

    #[test]
    fn capacities_are_powers_of_two_that_hold_every_slot_a_subscriber_may_hold() {
        assert_eq!(capacity_for(0), 64);
        assert_eq!(capacity_for(32), 64);
        assert_eq!(capacity_for(100), 128);
        assert_eq!(capacity_for(usize::MAX), MAX_CAPACITY);
        assert_eq!(ring_len(64), PAGE);
        assert!(check_capacity(96).is_err());
        assert!(RingReader::create(32).is_err());
        let reader = RingReader::create(128).expect("create");
        let fd = reader.fd().as_fd().try_clone_to_owned().expect("dup");
        assert!(
            RingWriter::open(fd, 64).is_err(),
            "a capacity other than the ring's"
        );
    }

    #[test]
    fn writers_on_two_threads_and_a_reader_lose_nothing() {
        let (mut reader, writer) = pair(64);
        let writer = std::sync::Arc::new(std::sync::Mutex::new(writer));
        let mut threads = Vec::new();
        for t in 0..2u32 {
            let writer = writer.clone();
            threads.push(std::thread::spawn(move || {
                let mut rang = 0;
                for i in 0..10_000u32 {
                    loop {
                        let pushed = writer.lock().expect("lock").push(t, i);
                        match pushed {
                            Pushed::Full => std::thread::yield_now(),
                            Pushed::Ring => {
                                rang += 1;
                                break;
                            }
                            Pushed::Quiet => break,
                        }
                    }
                }
                rang
            }));
        }
        let mut seen = [0u32; 2];
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
        while seen.iter().sum::<u32>() < 20_000 {
            assert!(std::time::Instant::now() < deadline, "seen {seen:?}");
            reader.arm();
            reader
                .take(|t, i| {
                    assert_eq!(i, seen[t as usize], "in order per writer");
                    seen[t as usize] += 1;
                })
                .expect("take");
        }
        let rang: u32 = threads.into_iter().map(|t| t.join().expect("join")).sum();
        assert!(rang > 0, "an armed ring asks to be rung");
    }
}
