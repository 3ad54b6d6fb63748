//! The channels this client owns, as the reader and the handles share them, and
//! the service requests the reader delivers to them.

use std::sync::Mutex;
use std::sync::atomic::{AtomicI32, Ordering};

use bytes::Bytes;
use tokio::sync::{mpsc, watch};

use super::frame::{OutFrame, encode};
use crate::error::FlowError;
use crate::protocol::{CallId, ChanId, ChannelKind, Command};
use crate::queue::lock;

/// A channel this client created, remembered so a reconnect can re-create it.
#[derive(Debug)]
pub(super) struct Owned {
    pub(super) name: String,
    kind: ChannelKind,
    pub(super) header: Mutex<String>,
    /// Current id, or -1 while the channel does not exist on the hub.
    id: AtomicI32,
    pub(super) listening: watch::Sender<bool>,
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

    /// Hands a request to the service's handler; `out` is the client's queue to
    /// the writer, which the request keeps to send its response.
    pub(super) fn deliver_call(
        &self,
        chan: ChanId,
        call: CallId,
        payload: Bytes,
        out: &mpsc::Sender<OutFrame>,
    ) {
        let sender = lock(&self.calls).clone();
        let Some(sender) = sender else { return };
        let request = ServiceCall {
            channel: chan,
            call,
            payload,
            out: out.clone(),
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
            let _ = out.try_send(encode(0, reply));
        }
    }

    pub(super) fn close(&self) {
        lock(&self.calls).take();
    }
}

/// One request to a service; answer it with [`ServiceCall::respond`]. A call
/// dropped unanswered is answered with an error, so no caller waits forever.
#[derive(Debug)]
pub struct ServiceCall {
    pub channel: ChanId,
    pub call: CallId,
    pub payload: Bytes,
    /// The client's queue to the writer: all a response needs of the client.
    out: mpsc::Sender<OutFrame>,
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
        self.out.send(frame).await.map_err(|_| FlowError::Closed)
    }
}

impl Drop for ServiceCall {
    fn drop(&mut self) {
        if !self.answered {
            let reply = Command::Respond {
                call: self.call,
                result: Err("request dropped unanswered".into()),
            };
            let _ = self.out.try_send(encode(0, reply));
        }
    }
}
