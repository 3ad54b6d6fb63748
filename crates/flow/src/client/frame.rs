//! Frames on their way to the session's writer, and the small encoding helpers
//! every part of the client shares.

use bytes::{Bytes, BytesMut};

use crate::error::FlowError;
use crate::protocol::{ChanId, Command, Envelope, ReqId, encode_command};

/// Encodes a command with its request id as one frame (request id 0 wants no reply).
pub(super) fn encode(req: ReqId, command: Command) -> OutFrame {
    let mut buf = BytesMut::new();
    encode_command(&Envelope { req, command }, &mut buf);
    OutFrame {
        head: buf.freeze(),
        payload: Bytes::new(),
        chan: None,
    }
}

/// One frame on its way to the session's writer: encoded bytes, then a large
/// publish's payload, which follows its header uncopied (the writer sends it
/// from the caller's own buffer, as the hub does for subscribers).
#[derive(Debug)]
pub(crate) struct OutFrame {
    head: Bytes,
    payload: Bytes,
    /// The channel of a large publish, whose payload may go into shared memory instead (`shm.rs`).
    chan: Option<ChanId>,
}

impl OutFrame {
    /// A `Publish` on `chan`: the payload is copied next to its header when
    /// small, and travels as its own piece when large.
    pub(super) fn publish(chan: ChanId, payload: Bytes) -> OutFrame {
        if payload.len() < crate::connection::ZERO_COPY_MIN {
            return encode(0, Command::Publish { chan, payload });
        }
        let mut head = BytesMut::with_capacity(16);
        crate::protocol::codec::encode_publish_head(chan, payload.len(), &mut head);
        OutFrame {
            head: head.freeze(),
            payload,
            chan: Some(chan),
        }
    }

    /// The channel, when this is a large publish.
    pub(super) fn publish_chan(&self) -> Option<ChanId> {
        self.chan
    }

    /// A large publish's payload (empty otherwise).
    pub(super) fn payload(&self) -> &Bytes {
        &self.payload
    }

    /// Hands the frame to `writer`'s next batch.
    pub(super) fn queue_on<W: crate::transport::TransportWrite>(
        self,
        writer: &mut crate::connection::FrameWriter<W>,
    ) {
        writer.queue_encoded(self.head);
        if !self.payload.is_empty() {
            writer.queue_encoded(self.payload);
        }
    }
}

/// Refuses text that is not JSON, before it reaches the hub as a channel header.
pub(super) fn check_json(text: &str) -> Result<(), FlowError> {
    serde_json::from_str::<serde_json::Value>(text)
        .map(drop)
        .map_err(|e| FlowError::Json(e.to_string()))
}
