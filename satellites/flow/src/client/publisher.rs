//! Owning side of channels: publishers of streams and servers of services.

use std::sync::Mutex;
use std::sync::atomic::{AtomicI32, AtomicU64, Ordering};

use bytes::Bytes;
use tokio::sync::{mpsc, watch};

use super::{Client, OutFrame, encode};
use crate::error::FlowError;
use crate::protocol::{CallId, ChanId, ChannelKind, Command};
use crate::queue::lock;

/// A channel this client created, remembered so a reconnect can re-create it.
#[derive(Debug)]
pub(super) struct Owned {
    pub(super) name: String,
    kind: ChannelKind,
    header: Mutex<String>,
    /// Current id, or -1 while the channel does not exist on the hub.
    id: AtomicI32,
    listening: watch::Sender<bool>,
    calls: Mutex<Option<mpsc::Sender<ServiceCall>>>,
}

impl Owned {
    pub(super) fn new(
        name: &str,
        kind: ChannelKind,
        header: &str,
        calls: Option<mpsc::Sender<ServiceCall>>,
    ) -> Self {
        Owned {
            name: name.to_string(),
            kind,
            header: Mutex::new(header.to_string()),
            id: AtomicI32::new(-1),
            listening: watch::channel(false).0,
            calls: Mutex::new(calls),
        }
    }

    pub(super) fn add_command(&self) -> Command {
        Command::AddChannel {
            kind: self.kind,
            name: self.name.clone(),
            header: lock(&self.header).clone(),
        }
    }

    pub(super) fn id(&self) -> Option<ChanId> {
        // The "no channel" marker -1 fits in an i16 too, so it must be excluded
        // explicitly: only 0..=32767 are channel ids.
        let raw = self.id.load(Ordering::Acquire);
        if raw < 0 {
            None
        } else {
            ChanId::try_from(raw).ok()
        }
    }

    pub(super) fn set_id(&self, id: Option<ChanId>) {
        self.id.store(id.map_or(-1, i32::from), Ordering::Release);
        if id.is_none() {
            self.set_listening(false);
        }
    }

    pub(super) fn set_listening(&self, on: bool) {
        self.listening.send_replace(on);
    }

    pub(super) fn deliver_call(&self, chan: ChanId, call: CallId, payload: Bytes, client: Client) {
        let sender = lock(&self.calls).clone();
        let Some(sender) = sender else { return };
        let request = ServiceCall {
            channel: chan,
            call,
            payload,
            client: client.clone(),
            answered: false,
        };
        if let Err(err) = sender.try_send(request) {
            // The handler is this far behind (or gone): answer at once rather
            // than let the caller wait for its timeout.
            let mut request = err.into_inner();
            request.answered = true;
            let reply = Command::Respond {
                call,
                result: Err("service overloaded".into()),
            };
            let _ = client.inner.out.try_send(encode(0, reply));
        }
    }

    pub(super) fn close(&self) {
        lock(&self.calls).take();
    }
}

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
        super::check_json(header)?;
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

/// One request to a service; answer it with [`ServiceCall::respond`]. A call
/// dropped unanswered is answered with an error, so no caller waits forever.
#[derive(Debug)]
pub struct ServiceCall {
    pub channel: ChanId,
    pub call: CallId,
    pub payload: Bytes,
    client: Client,
    answered: bool,
}

impl ServiceCall {
    /// Sends the response (or an error message) back to the caller.
    pub async fn respond(mut self, result: Result<Bytes, String>) -> Result<(), FlowError> {
        self.answered = true;
        let frame = encode(
            0,
            Command::Respond {
                call: self.call,
                result,
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

impl Drop for ServiceCall {
    fn drop(&mut self) {
        if !self.answered {
            let reply = Command::Respond {
                call: self.call,
                result: Err("request dropped unanswered".into()),
            };
            let _ = self.client.inner.out.try_send(encode(0, reply));
        }
    }
}
