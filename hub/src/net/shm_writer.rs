//! A connection writer's turn of a payload that lies in a shared-memory segment into a `DataRef`, introducing the
//! segment first with a read-only descriptor beside its frame; and the descriptor that goes with a granted segment.

use std::collections::HashSet;
use std::io;
use std::os::fd::AsFd;
use std::sync::Arc;

use flow::connection::FrameWriter;
use flow::protocol::{ErrorCode, ErrorReply, Event, Reply};
use flow::shm::ring::{self, Overrun, RingReader};
use flow::transport::TransportWrite;
use tracing::warn;

use crate::hub::{Segments, ShmPeer};

/// The writer's part: which segments this connection already maps.
#[derive(Debug)]
pub struct ShmWriter {
    peer: Arc<ShmPeer>,
    segments: Arc<Segments>,
    known: HashSet<u32>,
    /// The release ring was sent (or could not be made): once per connection.
    ring_offered: bool,
}

/// A subscriber that broke its release ring loses its connection, with the reason.
fn ring_broken(e: Overrun) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, e.to_string())
}

impl ShmWriter {
    pub fn new(peer: Arc<ShmPeer>, segments: Arc<Segments>) -> Self {
        ShmWriter {
            peer,
            segments,
            known: HashSet::new(),
            ring_offered: false,
        }
    }

    /// The outbox is empty: the subscriber rings for its next release from now on (see `hub/shm_peer.rs`).
    pub fn idle(&self) -> io::Result<()> {
        self.peer.writer_idle().map_err(ring_broken)
    }

    /// Work came: the writer reads the ring itself before each message by reference.
    pub fn busy(&self) {
        self.peer.writer_busy();
    }

    /// Sends this subscriber its release ring, before its first segment. A ring that cannot be made leaves it
    /// giving slots back in frames, as before rings.
    async fn offer_ring<W: TransportWrite>(
        &mut self,
        writer: &mut FrameWriter<W>,
    ) -> io::Result<()> {
        self.ring_offered = true;
        let capacity = ring::capacity_for(self.peer.max_held());
        let ring = match RingReader::create(capacity) {
            Ok(ring) => ring,
            Err(e) => {
                warn!(
                    "no release ring for a shared-memory subscriber, it gives slots back in frames: {e}"
                );
                return Ok(());
            }
        };
        writer
            .send_event_with_fd(&Event::ReleaseRing { capacity }, ring.fd())
            .await?;
        self.peer.set_ring(ring);
        Ok(())
    }

    /// Queues `event` on `writer`, by reference where it can; flushes before a frame that carries a descriptor.
    pub async fn queue<W: TransportWrite>(
        &mut self,
        writer: &mut FrameWriter<W>,
        event: Event,
    ) -> io::Result<()> {
        match event {
            Event::Data {
                chan,
                seq,
                ts_us,
                payload,
            } if self.peer.accepted()
                && payload.len() >= self.segments.settings().threshold as usize =>
            {
                // A subscriber that keeps many messages (a ring of recent frames) gets the rest as bytes (counted):
                // its writer never waits on it, so its other channels and its queue go on as for any subscriber.
                let mut by_reference = self.segments.locate(&payload);
                if by_reference.is_some() {
                    // What the subscriber put in its ring since the last look comes back first.
                    let held = self.peer.reclaim().map_err(ring_broken)?;
                    if held >= self.peer.max_held() {
                        self.segments.stats().count_inline();
                        by_reference = None;
                    }
                }
                let Some((segment, slot)) = by_reference else {
                    writer.queue_event(&Event::Data {
                        chan,
                        seq,
                        ts_us,
                        payload,
                    });
                    return Ok(());
                };
                if !self.ring_offered {
                    self.offer_ring(writer).await?;
                }
                if !self.known.contains(&slot.segment) {
                    let fd = segment.mapping().read_only_fd()?;
                    writer
                        .send_event_with_fd(&Event::Segment(segment.info), fd.as_fd())
                        .await?;
                    self.known.insert(slot.segment);
                }
                self.peer.hold(slot, payload);
                writer.queue_event(&Event::DataRef {
                    chan,
                    seq,
                    ts_us,
                    slot,
                });
            }
            // The segment a publisher asked for goes with its read-write descriptor.
            Event::Reply {
                req,
                result: Ok(Reply::Segment(info)),
            } => match self.segments.get(info.id) {
                Some(segment) => {
                    let event = Event::Reply {
                        req,
                        result: Ok(Reply::Segment(info)),
                    };
                    writer
                        .send_event_with_fd(&event, segment.mapping().fd())
                        .await?;
                }
                None => writer.queue_event(&Event::Reply {
                    req,
                    result: Err(ErrorReply::new(
                        ErrorCode::NotFound,
                        "the segment is gone: its channel was removed",
                    )),
                }),
            },
            other => writer.queue_event(&other),
        }
        Ok(())
    }
}
