//! Owning side of channels: publishers of streams and servers of services.

use std::sync::atomic::{AtomicU64, Ordering};

use bytes::Bytes;
use tokio::sync::{mpsc, watch};

use super::core::Client;
use super::frame::{OutFrame, check_json, encode};
use super::owned::{Owned, ServiceCall};
use crate::error::FlowError;
use crate::protocol::{ChanId, Command, SlotRef};
use crate::queue::lock;
use crate::shm::SlotMut;

/// Publishes on a streaming channel this client owns. Dropping it removes the channel.
#[derive(Debug)]
pub struct Publisher {
    owned: std::sync::Arc<Owned>,
    client: Client,
    skipped: AtomicU64,
}

impl Publisher {
    pub(super) fn new(owned: std::sync::Arc<Owned>, client: Client) -> Self {
        Publisher {
            owned,
            client,
            skipped: AtomicU64::new(0),
        }
    }

    pub fn name(&self) -> &str {
        &self.owned.name
    }

    pub fn id(&self) -> Option<ChanId> {
        self.owned.id()
    }

    /// Sends one message, waiting if the link's send queue is full.
    pub async fn publish(&self, payload: impl Into<Bytes>) -> Result<(), FlowError> {
        let frame = self.frame(payload.into())?;
        self.client
            .inner
            .out
            .send(frame)
            .await
            .map_err(|_| FlowError::Closed)
    }

    /// Sends one message unless the link's send queue is full, in which case
    /// the message is dropped and counted; returns whether it was queued.
    pub fn try_publish(&self, payload: impl Into<Bytes>) -> Result<bool, FlowError> {
        let frame = self.frame(payload.into())?;
        match self.client.inner.out.try_send(frame) {
            Ok(()) => Ok(true),
            Err(mpsc::error::TrySendError::Full(_)) => {
                self.skipped.fetch_add(1, Ordering::Relaxed);
                Ok(false)
            }
            Err(mpsc::error::TrySendError::Closed(_)) => Err(FlowError::Closed),
        }
    }

    fn frame(&self, payload: Bytes) -> Result<OutFrame, FlowError> {
        let chan = self
            .owned
            .id()
            .ok_or_else(|| FlowError::NotReady(self.owned.name.clone()))?;
        Ok(OutFrame::publish(chan, payload))
    }

    /// A slot of this channel's shared-memory segment to write a message of up to `len` bytes into, in place: the
    /// zero-copy way to publish a large message (a camera frame decoded or rendered straight into it). `None` when
    /// the link has no shared memory (not a Unix socket, or the hub's is off), when the channel's segment is not
    /// there yet (it is asked for now: the next call may have it), or when every slot is still held; then publish
    /// the message with [`Publisher::publish`], which never waits for a slot either.
    pub fn loan(&self, len: usize) -> Option<Loan> {
        let chan = self.owned.id()?;
        let shm = self.client.shm_session()?;
        let (info, slot) = shm.loan(chan, len, |chan, slot_size| {
            self.client.ask_segment(chan, slot_size)
        })?;
        Some(Loan {
            chan,
            segment: info.id,
            slot,
            client: self.client.clone(),
        })
    }

    /// Messages `try_publish` dropped because the link was saturated.
    pub fn skipped(&self) -> u64 {
        self.skipped.load(Ordering::Relaxed)
    }

    /// Whether anyone subscribes now (the hub says when the first arrives and the last leaves).
    pub fn has_subscribers(&self) -> bool {
        *self.owned.listening.borrow()
    }

    /// Watches whether anyone subscribes, to publish only while someone listens.
    pub fn subscribers(&self) -> watch::Receiver<bool> {
        self.owned.listening.subscribe()
    }

    /// Replaces the channel's JSON header; everyone is told.
    pub async fn set_header(&self, header: &str) -> Result<(), FlowError> {
        check_json(header)?;
        *lock(&self.owned.header) = header.to_string();
        let chan = self
            .owned
            .id()
            .ok_or_else(|| FlowError::NotReady(self.owned.name.clone()))?;
        self.client
            .request(Command::SetHeader {
                chan,
                header: header.to_string(),
            })
            .await
            .map(drop)
    }
}

/// A message being written in place into a shared-memory slot ([`Publisher::loan`]). Dropping it unpublished
/// frees the slot.
#[derive(Debug)]
pub struct Loan {
    chan: ChanId,
    segment: u32,
    slot: SlotMut,
    client: Client,
}

impl Loan {
    /// The message's bytes, to write.
    pub fn as_mut_slice(&mut self) -> &mut [u8] {
        self.slot.as_mut_slice()
    }

    pub fn len(&self) -> usize {
        self.slot.len()
    }

    pub fn is_empty(&self) -> bool {
        self.slot.is_empty()
    }

    /// Shortens the message to `len` bytes (loaned at its largest size, written shorter).
    pub fn truncate(&mut self, len: usize) {
        self.slot.truncate(len);
    }

    /// Publishes the message, waiting if the link's send queue is full (as [`Publisher::publish`]).
    pub async fn publish(self) -> Result<(), FlowError> {
        let (slot, len) = self.slot.hand_over();
        let slot = SlotRef {
            segment: self.segment,
            slot,
            len: len as u32,
        };
        let frame = encode(
            0,
            Command::PublishRef {
                chan: self.chan,
                slot,
            },
        );
        self.client
            .inner
            .out
            .send(frame)
            .await
            .map_err(|_| FlowError::Closed)
    }
}

impl Drop for Publisher {
    fn drop(&mut self) {
        self.client.release_owned(&self.owned);
    }
}

/// A service channel this client owns. Dropping it removes the channel.
#[derive(Debug)]
pub struct Service {
    owned: std::sync::Arc<Owned>,
    calls: mpsc::Receiver<ServiceCall>,
    client: Client,
}

impl Service {
    pub(super) fn new(
        owned: std::sync::Arc<Owned>,
        calls: mpsc::Receiver<ServiceCall>,
        client: Client,
    ) -> Self {
        Service {
            owned,
            calls,
            client,
        }
    }

    pub fn name(&self) -> &str {
        &self.owned.name
    }

    /// The next request; `None` once the client has shut down.
    pub async fn next(&mut self) -> Option<ServiceCall> {
        self.calls.recv().await
    }
}

impl Drop for Service {
    fn drop(&mut self) {
        self.client.release_owned(&self.owned);
    }
}
