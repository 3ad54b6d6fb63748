//! A session's shared memory, on the client's side: the segments the hub introduced (subscriber), the segments this
//! client publishes into (publisher), and the slots waiting to be given back.
//!
//! A session has it only over the Unix socket, after the hub accepted `ShmAccept` (`session.rs` asks at login). It
//! lives and dies with the session: a reconnected client starts with none, as the new hub knows none.

use std::collections::HashMap;
use std::os::fd::OwnedFd;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::Notify;
use tokio::time::Instant;

use super::frame::{OutFrame, encode};
use crate::protocol::{ChanId, Command, Event, Reply, SegmentInfo, SlotRef};
use crate::queue::lock;
use crate::shm::ring::{Pushed, RingWriter};
use crate::shm::{Mapping, SlotMut, SlotOwner, layout, slot_bytes};

/// The shared memory of one session.
#[derive(Debug)]
pub(super) struct ShmSession {
    /// Payloads from this size go into a slot (the hub's `hub.shm_threshold`).
    threshold: usize,
    /// Segments the hub introduced, by id: what `DataRef`s point into.
    received: Mutex<HashMap<u32, Received>>,
    /// This client's own segments, by channel.
    publishing: Mutex<HashMap<ChanId, Publishing>>,
    releases: Arc<Releases>,
    /// Large messages that went inline because every slot of their segment was held.
    spilled: Arc<AtomicU64>,
    /// Map the release ring the hub offers (`ConnectOptions::release_ring`).
    use_ring: bool,
}

#[derive(Debug)]
struct Received {
    info: SegmentInfo,
    map: Arc<Mapping>,
    owner: Arc<dyn SlotOwner>,
}

/// A channel's segments on the publishing side: a stream whose messages grow gets bigger ones beside the first.
#[derive(Debug, Default)]
struct Publishing {
    /// The segments granted, smallest slots first.
    ready: Vec<(SegmentInfo, Arc<Mapping>)>,
    /// A segment asked for and not granted yet: messages that fit none of `ready` go inline meanwhile.
    asked: bool,
    /// The hub refused one (its limit per channel): messages that fit none of `ready` go inline.
    refused: bool,
}

/// Slots dropped by their last holder and not yet given back. With the hub's release ring they go there, and the
/// writer sends an empty `Release` only when the hub asks to be rung; without it (or when it is full) the writer
/// sends them as one `Release`. Bounded by the slots the hub lets this client hold at once.
#[derive(Debug, Default)]
pub(super) struct Releases {
    pending: Mutex<Pending>,
    pub(super) wake: Notify,
}

#[derive(Debug, Default)]
struct Pending {
    /// Slots for the next `Release` frame.
    slots: Vec<SlotRef>,
    /// The ring the hub made for this session, once it sent it.
    ring: Option<RingWriter>,
    /// A release went into the ring while the hub was idle: ring it after [`RING_DELAY`] unless it woke meanwhile.
    ring_wanted: bool,
}

/// How long a release written while the hub is idle waits before the hub is rung. A stream of a few hundred
/// messages a second or more never rings: the hub wakes for the next message first and takes the releases itself.
/// Slower streams ring once per quiet spell, as they sent one `Release` frame per message before the ring.
pub(super) const RING_DELAY: Duration = Duration::from_millis(5);

/// Gives a received segment's slots back through [`Releases`].
#[derive(Debug)]
struct GiveBack {
    segment: u32,
    releases: Arc<Releases>,
}

impl SlotOwner for GiveBack {
    fn release(&self, slot: u32) {
        let mut pending = lock(&self.releases.pending);
        let pushed = match pending.ring.as_mut() {
            Some(ring) => ring.push(self.segment, slot),
            None => Pushed::Full,
        };
        match pushed {
            // The hub takes it from the ring on its own: no frame, no wake-up of the writer.
            Pushed::Quiet => return,
            // The writer rings after a while (and is woken now only to set its timer).
            Pushed::Ring if pending.ring_wanted => return,
            Pushed::Ring => pending.ring_wanted = true,
            Pushed::Full => pending.slots.push(SlotRef {
                segment: self.segment,
                slot,
                len: 0,
            }),
        }
        drop(pending);
        self.releases.wake.notify_one();
    }
}

impl ShmSession {
    pub(super) fn new(threshold: u32, spilled: Arc<AtomicU64>, use_ring: bool) -> Self {
        ShmSession {
            threshold: (threshold as usize).max(crate::connection::ZERO_COPY_MIN),
            received: Mutex::new(HashMap::new()),
            publishing: Mutex::new(HashMap::new()),
            releases: Arc::new(Releases::default()),
            spilled,
            use_ring,
        }
    }

    pub(super) fn releases(&self) -> &Arc<Releases> {
        &self.releases
    }

    /// The `Release` command to send now, if any: the slots given back in frames since the last one, or an empty
    /// one that rings an idle hub once `ring_at` (set here when a ring is wanted) has come.
    pub(super) fn take_releases(
        &self,
        now: Instant,
        ring_at: &mut Option<Instant>,
    ) -> Option<OutFrame> {
        let mut pending = lock(&self.releases.pending);
        let slots = std::mem::take(&mut pending.slots);
        let ring = if !slots.is_empty() {
            // Any `Release` makes the hub read the ring.
            true
        } else if !pending.ring_wanted {
            false
        } else if let Some(at) = *ring_at
            && at <= now
        {
            // The hub that woke since takes the ring at its next idle look: then no frame is needed.
            pending.ring.as_ref().is_some_and(RingWriter::hub_idle)
        } else {
            ring_at.get_or_insert(now + RING_DELAY);
            return None;
        };
        pending.ring_wanted = false;
        *ring_at = None;
        ring.then(|| encode(0, Command::Release { slots }))
    }

    /// Turns what the hub sent into what the rest of the client handles: a segment is mapped and kept (`None`), a
    /// `DataRef` becomes `Data` whose payload is the slot itself, a granted segment is mapped before its reply goes
    /// on. `take_fd` yields the descriptors that came beside the bytes, in order. An error ends the session.
    pub(super) fn receive(
        &self,
        event: Event,
        take_fd: impl FnOnce() -> Option<OwnedFd>,
    ) -> Result<Option<Event>, String> {
        match event {
            Event::Segment(info) => {
                let map = map_segment(&info, take_fd, false)?;
                let owner: Arc<dyn SlotOwner> = Arc::new(GiveBack {
                    segment: info.id,
                    releases: self.releases.clone(),
                });
                lock(&self.received).insert(info.id, Received { info, map, owner });
                Ok(None)
            }
            Event::ReleaseRing { capacity } => {
                let fd = take_fd().ok_or("the release ring came without its descriptor")?;
                if !self.use_ring {
                    // Declined: the descriptor closes here, and slots go back in frames.
                    return Ok(None);
                }
                let ring =
                    RingWriter::open(fd, capacity).map_err(|e| format!("the release ring: {e}"))?;
                lock(&self.releases.pending).ring = Some(ring);
                Ok(None)
            }
            Event::Reply {
                result: Ok(Reply::Segment(info)),
                ..
            } => {
                let map = map_segment(&info, take_fd, true)?;
                let mut publishing = lock(&self.publishing);
                let channel = publishing.entry(info.chan).or_default();
                channel.asked = false;
                channel.ready.push((info, map));
                channel.ready.sort_by_key(|(info, _)| info.slot_size);
                Ok(Some(event))
            }
            Event::DataRef {
                chan,
                seq,
                ts_us,
                slot,
            } => {
                let payload = {
                    let received = lock(&self.received);
                    received.get(&slot.segment).and_then(|r| {
                        if slot.slot >= r.info.slots || slot.len > r.info.slot_size {
                            return None;
                        }
                        let offset = layout::slot_offset(r.info.slots, r.info.slot_size, slot.slot);
                        slot_bytes(
                            r.map.clone(),
                            offset,
                            slot.len as usize,
                            slot.slot,
                            r.owner.clone(),
                        )
                    })
                };
                match payload {
                    Some(payload) => Ok(Some(Event::Data {
                        chan,
                        seq,
                        ts_us,
                        payload,
                    })),
                    None => Err(format!(
                        "the hub sent a message in slot {} of segment {}, which this client does not map",
                        slot.slot, slot.segment
                    )),
                }
            }
            Event::ChannelRemoved { id, .. } => {
                // The channel's segments are gone for new messages; slots still held keep their mapping alive.
                lock(&self.received).retain(|_, r| r.info.chan != id);
                lock(&self.publishing).remove(&id);
                Ok(Some(event))
            }
            other => Ok(Some(other)),
        }
    }

    /// The frame to send for `frame`: a `PublishRef` when its payload went into a free slot of the channel's
    /// segment; the frame itself otherwise (small, no segment yet, or every slot held: then it is counted as
    /// spilled). Never waits: a missing segment is asked for in the background.
    pub(super) fn publish(&self, frame: OutFrame, ask: impl FnOnce(ChanId, u32)) -> OutFrame {
        let Some(chan) = frame.publish_chan() else {
            return frame;
        };
        let payload = frame.payload();
        if payload.len() < self.threshold {
            return frame;
        }
        let Some((info, mut slot)) = self.loan(chan, payload.len(), ask) else {
            return frame;
        };
        slot.as_mut_slice().copy_from_slice(payload);
        let (slot, len) = slot.hand_over();
        let slot = SlotRef {
            segment: info.id,
            slot,
            len: len as u32,
        };
        encode(0, Command::PublishRef { chan, slot })
    }

    /// A free slot of `chan`'s segment to write a message of `len` bytes into, in place. `None` while the segment is
    /// asked for (`ask(chan, slot_size)` asks for one when there is none that fits), when the hub refused one, or when
    /// every slot is held (counted as spilled: the message goes inline).
    pub(super) fn loan(
        &self,
        chan: ChanId,
        len: usize,
        ask: impl FnOnce(ChanId, u32),
    ) -> Option<(SegmentInfo, SlotMut)> {
        let mut publishing = lock(&self.publishing);
        let channel = publishing.entry(chan).or_default();
        let mut fitting = channel
            .ready
            .iter()
            .filter(|(info, _)| len <= info.slot_size as usize)
            .peekable();
        if fitting.peek().is_some() {
            // The smallest segment that fits with a free slot, and its lowest free slot, so that a stream touches
            // as few pages as it needs.
            let taken = fitting.find_map(|(info, map)| {
                (0..info.slots)
                    .find_map(|slot| map.take_slot(info.slots, info.slot_size, slot, len))
                    .map(|slot| (*info, slot))
            });
            if taken.is_none() {
                self.spilled.fetch_add(1, Ordering::Relaxed);
            }
            return taken;
        }
        if !channel.asked && !channel.refused {
            // Four times the largest slot so far at least, so that a stream whose messages grow step by step
            // needs few segments (the hub allows `hub.shm_segments_per_channel`).
            let largest = channel
                .ready
                .last()
                .map_or(0, |(info, _)| info.slot_size as usize);
            let slot_size = layout::slot_size_for(len.max(largest.saturating_mul(4)))
                .or_else(|| layout::slot_size_for(len))?;
            channel.asked = true;
            ask(chan, slot_size);
        }
        None
    }

    /// Records that the hub refused a segment for `chan`.
    pub(super) fn refused(&self, chan: ChanId) {
        let mut publishing = lock(&self.publishing);
        let channel = publishing.entry(chan).or_default();
        channel.asked = false;
        channel.refused = true;
    }
}

/// Maps a segment the hub introduced, from the next descriptor that came.
fn map_segment(
    info: &SegmentInfo,
    take_fd: impl FnOnce() -> Option<OwnedFd>,
    writable: bool,
) -> Result<Arc<Mapping>, String> {
    let fd = take_fd().ok_or_else(|| format!("segment {} came without its descriptor", info.id))?;
    layout::check_shape(info.slots, info.slot_size)
        .map_err(|e| format!("segment {}: {e}", info.id))?;
    let len = layout::segment_len(info.slots, info.slot_size);
    Mapping::open(fd, len, writable)
        .map(Arc::new)
        .map_err(|e| format!("segment {}: {e}", info.id))
}
