//! FlowProtocol and the satellite SDK: the one crate that the hub and every
//! satellite share.
//!
//! - [`protocol`]: frames, messages and their encoding, pure functions over bytes.
//! - [`transport`]: TCP, Unix socket, WebSocket and in-process links.
//! - [`connection`]: framing over a transport.
//! - [`client`]: the SDK: log in, create channels, publish, subscribe, serve and
//!   call services, use the pair database, reconnect automatically.
//! - [`shm`]: shared-memory segments and slots for clients on the hub's machine.
//! - [`sketch`]: the setup-then-loop programming style of the paper's PySketch.
//! - [`log`]: the log every binary installs (feature `logging`) and [`log::Throttle`] for repeated warnings.

pub mod client;
pub mod connection;
pub mod error;
pub mod log;
pub mod priority;
pub mod protocol;
pub mod queue;
pub mod shm;
pub mod sketch;
pub mod tick;
pub mod token;
pub mod transport;

pub use client::{
    Client, ClientEvent, ConnectOptions, Data, Loan, Publisher, Service, ServiceCall, Subscription,
};
pub use error::FlowError;
pub use protocol::{ChanId, ChannelInfo, ChannelKind, ChannelStats, ErrorCode};
pub use transport::FlowAddr;
