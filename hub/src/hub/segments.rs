//! The shared-memory segments of the hub's channels: made on a publisher's request (`ShmOpen`), leased slot by slot
//! as it publishes (`PublishRef`), and retired with their channel.
//!
//! A leased slot is a [`Bytes`] over the hub's own mapping, so the fan-out, the queues, the recorder and federation
//! carry it like any payload; when its last clone is dropped (every subscriber's queue sent or dropped it, every
//! shared-memory subscriber gave it back) the slot's state word in the segment turns free and the publisher may
//! write it again. The hub never trusts that word: it keeps its own lease flags, and a publisher that publishes a
//! slot the hub still holds breaks the protocol.
//!
//! A segment lives while its channel does or any of its slots is held; then it is unmapped and its descriptor
//! closed, and the kernel frees it once no process maps it. Nothing of it is ever in `/dev/shm`.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, Weak};

use bytes::Bytes;
use flow::protocol::{ChanId, SegmentInfo, SlotRef};
use flow::shm::{Mapping, SlotOwner, layout, slot_bytes};

/// A connection's id (`hub::ConnId`), spelled out so that this file needs nothing from the hub's core.
type ConnId = u32;

/// `[hub] shm*`: the shared-memory path's settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShmSettings {
    /// Offered to Unix-socket clients at all.
    pub enabled: bool,
    /// Payloads from this size go by reference.
    pub threshold: u32,
    /// Slots per segment.
    pub slots: u32,
    /// Segments one channel may have (a stream whose messages grow gets a bigger one; the older stay until the
    /// channel goes).
    pub per_channel: usize,
    /// Slots one subscriber may hold at once (received and not given back yet); past it, its writer waits and its
    /// queue drops the oldest, as for any slow subscriber.
    pub held: usize,
}

impl Default for ShmSettings {
    fn default() -> Self {
        ShmSettings {
            enabled: true,
            threshold: 4096,
            slots: 128,
            per_channel: 8,
            held: 32,
        }
    }
}

/// Figures for `/metrics`.
#[derive(Debug, Default)]
pub struct ShmStats {
    segments: AtomicI64,
    slots_held: AtomicI64,
    messages: AtomicU64,
    inline: AtomicU64,
    released_by_frame: AtomicU64,
    released_by_ring: AtomicU64,
}

impl ShmStats {
    /// Segments alive now (a retired one stays until its last slot is given back).
    pub fn segments(&self) -> i64 {
        self.segments.load(Ordering::Relaxed)
    }
    /// Slots whose message someone (a queue, a subscriber, the recorder) holds now.
    pub fn slots_held(&self) -> i64 {
        self.slots_held.load(Ordering::Relaxed)
    }
    /// Messages published by reference since the start.
    pub fn messages(&self) -> u64 {
        self.messages.load(Ordering::Relaxed)
    }
    /// Deliveries of such messages as bytes to a shared-memory subscriber that held all the slots it may.
    pub fn inline(&self) -> u64 {
        self.inline.load(Ordering::Relaxed)
    }
    pub(crate) fn count_inline(&self) {
        self.inline.fetch_add(1, Ordering::Relaxed);
    }
    /// Slots subscribers gave back in `Release` frames.
    pub fn released_by_frame(&self) -> u64 {
        self.released_by_frame.load(Ordering::Relaxed)
    }
    /// Slots subscribers gave back through their release rings, with no frame.
    pub fn released_by_ring(&self) -> u64 {
        self.released_by_ring.load(Ordering::Relaxed)
    }
    pub(crate) fn count_released(&self, by_frame: u64, by_ring: u64) {
        if by_frame > 0 {
            self.released_by_frame
                .fetch_add(by_frame, Ordering::Relaxed);
        }
        if by_ring > 0 {
            self.released_by_ring.fetch_add(by_ring, Ordering::Relaxed);
        }
    }
}

/// Why a `PublishRef` was not taken.
#[derive(Debug, PartialEq, Eq)]
pub enum LeaseError {
    /// The segment is not (or no longer) this connection's on this channel: a channel removed a moment ago. The
    /// message is dropped and the connection goes on.
    Unknown(String),
    /// The publisher broke the protocol (a slot out of bounds, or published again before the hub freed it).
    Violation(String),
}

/// Every segment of the hub.
#[derive(Debug)]
pub struct Segments {
    settings: ShmSettings,
    stats: Arc<ShmStats>,
    inner: Arc<Mutex<Inner>>,
}

#[derive(Debug, Default)]
struct Inner {
    next_id: u32,
    /// Segments still in use by their channel, which hold them alive.
    by_chan: HashMap<ChanId, Vec<Arc<Segment>>>,
    /// Every segment alive, retired or not: where its mapping lies, to find a payload's slot.
    live: Vec<(usize, usize, u32, Weak<Segment>)>,
}

/// One segment.
#[derive(Debug)]
pub struct Segment {
    pub info: SegmentInfo,
    conn: ConnId,
    map: Arc<Mapping>,
    leased: Vec<AtomicBool>,
    stats: Arc<ShmStats>,
    registry: Weak<Mutex<Inner>>,
}

fn lock(inner: &Mutex<Inner>) -> MutexGuard<'_, Inner> {
    inner
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Default for Segments {
    fn default() -> Self {
        Segments::new(ShmSettings::default())
    }
}

impl Segments {
    pub fn new(settings: ShmSettings) -> Self {
        Segments {
            settings,
            stats: Arc::new(ShmStats::default()),
            inner: Arc::new(Mutex::new(Inner {
                next_id: 1,
                ..Inner::default()
            })),
        }
    }

    pub fn settings(&self) -> &ShmSettings {
        &self.settings
    }

    pub fn stats(&self) -> &ShmStats {
        &self.stats
    }

    /// The figures, for a connection's [`super::ShmPeer`] to count into.
    pub fn shared_stats(&self) -> Arc<ShmStats> {
        self.stats.clone()
    }

    /// A new segment for `conn`'s channel `chan` with slots of at least `slot_size` bytes. The caller checked that
    /// the channel is `conn`'s stream.
    pub fn open(&self, conn: ConnId, chan: ChanId, slot_size: u32) -> Result<SegmentInfo, String> {
        if !self.settings.enabled {
            return Err("shared memory is off on this hub (hub.shm)".into());
        }
        let slot_size = layout::slot_size_for(slot_size as usize)
            .ok_or_else(|| format!("slot size {slot_size} is over {}", layout::MAX_SLOT))?;
        let slots = self.settings.slots;
        layout::check_shape(slots, slot_size)?;
        let mut inner = lock(&self.inner);
        let count = inner.by_chan.get(&chan).map_or(0, Vec::len);
        if count >= self.settings.per_channel {
            return Err(format!(
                "channel {chan} has {count} segments already (hub.shm_segments_per_channel)"
            ));
        }
        let len = layout::segment_len(slots, slot_size);
        let map = Mapping::create("flow-shm", len).map_err(|e| format!("making a segment: {e}"))?;
        let id = inner.next_id;
        inner.next_id = inner.next_id.wrapping_add(1).max(1);
        let info = SegmentInfo {
            id,
            chan,
            slots,
            slot_size,
        };
        let start = map.bytes(0, len).map_or(0, |b| b.as_ptr() as usize);
        let segment = Arc::new(Segment {
            info,
            conn,
            map: Arc::new(map),
            leased: (0..slots).map(|_| AtomicBool::new(false)).collect(),
            stats: self.stats.clone(),
            registry: Arc::downgrade(&self.inner),
        });
        segment.write_header();
        inner
            .live
            .push((start, start + len, id, Arc::downgrade(&segment)));
        inner.by_chan.entry(chan).or_default().push(segment);
        self.stats.segments.fetch_add(1, Ordering::Relaxed);
        Ok(info)
    }

    /// Retires `chan`'s segments: no new message goes into them; each goes once its held slots come back.
    pub fn retire_channel(&self, chan: ChanId) {
        let gone = lock(&self.inner).by_chan.remove(&chan);
        // Dropped here, after the lock: the last reference's drop takes the lock itself.
        drop(gone);
    }

    /// The message in `slot` of `conn`'s segment on `chan`, as a payload that frees the slot when it is dropped.
    pub fn lease(&self, conn: ConnId, chan: ChanId, slot: SlotRef) -> Result<Bytes, LeaseError> {
        let segment = lock(&self.inner)
            .by_chan
            .get(&chan)
            .and_then(|list| list.iter().find(|s| s.info.id == slot.segment))
            .cloned()
            .filter(|s| s.conn == conn)
            .ok_or_else(|| {
                LeaseError::Unknown(format!(
                    "segment {} is not this connection's on channel {chan}",
                    slot.segment
                ))
            })?;
        let bytes = segment.lease(slot)?;
        self.stats.messages.fetch_add(1, Ordering::Relaxed);
        Ok(bytes)
    }

    /// The segment and slot a payload lies in, when it is a whole leased message (a slice of one is not).
    pub fn locate(&self, payload: &[u8]) -> Option<(Arc<Segment>, SlotRef)> {
        let at = payload.as_ptr() as usize;
        let segment = lock(&self.inner)
            .live
            .iter()
            .find(|(start, end, _, _)| *start <= at && at < *end)
            .and_then(|(_, _, _, weak)| weak.upgrade())?;
        let info = segment.info;
        let data = segment.map.bytes(0, 0)?.as_ptr() as usize + layout::data_offset(info.slots);
        let from_data = at.checked_sub(data)?;
        let slot = u32::try_from(from_data / info.slot_size as usize).ok()?;
        let starts_slot = from_data % info.slot_size as usize == 0;
        (starts_slot && slot < info.slots).then_some((
            segment,
            SlotRef {
                segment: info.id,
                slot,
                len: payload.len() as u32,
            },
        ))
    }

    /// A live segment by id (its descriptor goes with the reply that grants it).
    pub fn get(&self, id: u32) -> Option<Arc<Segment>> {
        // Only the match is upgraded: dropping another segment's last reference here would take the lock again.
        lock(&self.inner)
            .live
            .iter()
            .find(|(_, _, live, _)| *live == id)
            .and_then(|(_, _, _, weak)| weak.upgrade())
    }
}

impl Segment {
    /// The mapping, for its descriptors.
    pub fn mapping(&self) -> &Mapping {
        &self.map
    }

    fn write_header(&self) {
        let mut header = [0u8; 12];
        header[..4].copy_from_slice(&layout::MAGIC.to_le_bytes());
        header[4..8].copy_from_slice(&self.info.slots.to_le_bytes());
        header[8..].copy_from_slice(&self.info.slot_size.to_le_bytes());
        self.map.write(0, &header);
    }

    fn lease(self: &Arc<Self>, slot: SlotRef) -> Result<Bytes, LeaseError> {
        let info = self.info;
        if slot.slot >= info.slots || slot.len > info.slot_size {
            return Err(LeaseError::Violation(format!(
                "slot {} of {} bytes is outside segment {} ({} slots of {} bytes)",
                slot.slot, slot.len, info.id, info.slots, info.slot_size
            )));
        }
        let flag = &self.leased[slot.slot as usize];
        if flag.swap(true, Ordering::AcqRel) {
            return Err(LeaseError::Violation(format!(
                "slot {} of segment {} published again before the hub freed it",
                slot.slot, info.id
            )));
        }
        self.stats.slots_held.fetch_add(1, Ordering::Relaxed);
        let offset = layout::slot_offset(info.slots, info.slot_size, slot.slot);
        let owner: Arc<dyn SlotOwner> = self.clone();
        slot_bytes(
            self.map.clone(),
            offset,
            slot.len as usize,
            slot.slot,
            owner,
        )
        .ok_or_else(|| {
            // Cannot happen with a checked shape; undo the lease all the same.
            self.release(slot.slot);
            LeaseError::Violation(format!("slot {} is outside the mapping", slot.slot))
        })
    }
}

impl SlotOwner for Segment {
    fn release(&self, slot: u32) {
        let Some(flag) = self.leased.get(slot as usize) else {
            return;
        };
        // The hub's own flag first: once the publisher sees the slot free it may publish it again at once.
        if flag.swap(false, Ordering::AcqRel) {
            self.stats.slots_held.fetch_sub(1, Ordering::Relaxed);
        }
        if let Some(state) = self.map.state(self.info.slots, slot) {
            state.store(layout::FREE, Ordering::Release);
        }
    }
}

impl Drop for Segment {
    fn drop(&mut self) {
        self.stats.segments.fetch_sub(1, Ordering::Relaxed);
        if let Some(inner) = self.registry.upgrade() {
            lock(&inner)
                .live
                .retain(|(_, _, _, weak)| weak.strong_count() > 0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slot(segment: u32, slot: u32, len: u32) -> SlotRef {
        SlotRef { segment, slot, len }
    }

    #[test]
    fn a_leased_slot_is_freed_when_its_last_holder_lets_go() {
        let segments = Segments::new(ShmSettings::default());
        let info = segments.open(7, 3, 10_000).expect("open");
        assert_eq!(info.slot_size, 16_384);
        let segment = segments.get(info.id).expect("live");
        let state = segment.mapping().state(info.slots, 2).expect("state");
        state.store(layout::TAKEN, Ordering::Release);
        let payload = segments.lease(7, 3, slot(info.id, 2, 100)).expect("lease");
        assert_eq!(segments.stats().slots_held(), 1);
        let (found, at) = segments.locate(&payload).expect("located");
        assert_eq!((found.info.id, at.slot, at.len), (info.id, 2, 100));
        assert!(
            segments.locate(&payload[1..]).is_none(),
            "a slice is not a whole message"
        );
        let copy = payload.clone();
        drop(payload);
        assert_eq!(state.load(Ordering::Acquire), layout::TAKEN);
        drop(copy);
        assert_eq!(state.load(Ordering::Acquire), layout::FREE);
        assert_eq!(segments.stats().slots_held(), 0);
    }

    #[test]
    fn a_publisher_cannot_publish_a_held_slot_or_another_ones_segment() {
        let segments = Segments::new(ShmSettings::default());
        let info = segments.open(7, 3, 4096).expect("open");
        let held = segments.lease(7, 3, slot(info.id, 0, 10)).expect("lease");
        assert!(matches!(
            segments.lease(7, 3, slot(info.id, 0, 10)),
            Err(LeaseError::Violation(_))
        ));
        assert!(matches!(
            segments.lease(7, 3, slot(info.id, 128, 10)),
            Err(LeaseError::Violation(_))
        ));
        assert!(matches!(
            segments.lease(8, 3, slot(info.id, 1, 10)),
            Err(LeaseError::Unknown(_))
        ));
        drop(held);
    }

    #[test]
    fn a_retired_segment_lives_until_its_slots_come_back() {
        let segments = Segments::new(ShmSettings::default());
        let info = segments.open(7, 3, 4096).expect("open");
        let held = segments.lease(7, 3, slot(info.id, 5, 10)).expect("lease");
        segments.retire_channel(3);
        assert_eq!(segments.stats().segments(), 1);
        assert!(matches!(
            segments.lease(7, 3, slot(info.id, 6, 10)),
            Err(LeaseError::Unknown(_))
        ));
        drop(held);
        assert_eq!(segments.stats().segments(), 0);
        assert!(segments.get(info.id).is_none());
    }

    #[test]
    fn a_channel_has_a_bounded_number_of_segments() {
        let segments = Segments::new(ShmSettings::default());
        for k in 0..8 {
            segments.open(7, 3, 4096 << k).expect("open");
        }
        assert!(segments.open(7, 3, 4096 << 8).is_err());
    }
}
