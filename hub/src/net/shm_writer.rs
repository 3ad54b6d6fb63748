//! A connection writer's turn of a payload that lies in a shared-memory segment into a `DataRef`, introducing the
//! segment first with a read-only descriptor beside its frame; and the descriptor that goes with a granted segment.

use std::collections::HashSet;
use std::io;
use std::os::fd::AsFd;
use std::sync::Arc;

use flow::connection::FrameWriter;
use flow::protocol::{ErrorCode, ErrorReply, Event, Reply};
use flow::transport::TransportWrite;

use crate::hub::{Segments, ShmPeer};

/// The writer's part: which segments this connection already maps.
#[derive(Debug)]
pub struct ShmWriter {
    peer: Arc<ShmPeer>,
    segments: Arc<Segments>,
    known: HashSet<u32>,
}

impl ShmWriter {
    pub fn new(peer: Arc<ShmPeer>, segments: Arc<Segments>) -> Self {
        ShmWriter {
            peer,
            segments,
            known: HashSet::new(),
        }
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
                let by_reference = self.segments.locate(&payload).filter(|_| {
                    let room = self.peer.held() < self.peer.max_held();
                    if !room {
                        self.segments.stats().count_inline();
                    }
                    room
                });
                let Some((segment, slot)) = by_reference else {
                    writer.queue_event(&Event::Data {
                        chan,
                        seq,
                        ts_us,
                        payload,
                    });
                    return Ok(());
                };
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
