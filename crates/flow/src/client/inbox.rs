//! What the client's reader fills for each subscription: the messages and the
//! drop-oldest queue they wait in, shared by the reader and the handles.

use std::sync::Mutex;

use bytes::Bytes;

use crate::protocol::{ChanId, ChannelInfo};
use crate::queue::{DropOldest, lock};

/// One message from a streaming channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Data {
    pub channel: ChanId,
    /// Position on the channel, from 1; a gap means messages were dropped.
    pub seq: u64,
    /// Hub clock (µs since the Unix epoch) when the message was published.
    pub ts_us: u64,
    pub payload: Bytes,
}

/// The state one subscription handle shares with the reader.
#[derive(Debug)]
pub(super) struct SubShared {
    pub(super) name: String,
    pub(super) queue: DropOldest<Data>,
    info: Mutex<Option<ChannelInfo>>,
}

impl SubShared {
    pub(super) fn new(name: &str, capacity: usize) -> Self {
        SubShared {
            name: name.to_string(),
            queue: DropOldest::new(capacity),
            info: Mutex::new(None),
        }
    }

    pub(super) fn set_info(&self, info: ChannelInfo) {
        *lock(&self.info) = Some(info);
    }

    /// The channel's properties as of the last (re)subscription.
    pub(super) fn info(&self) -> Option<ChannelInfo> {
        lock(&self.info).clone()
    }
}
