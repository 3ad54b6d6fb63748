//! The robot-agent server: the flow hub (channels, services, pair database,
//! pulses), its transports (TCP, Unix socket, WebSocket), the HTTP edge and
//! the internal modules. See ARCHITECTURE.md for the map.

pub mod browser;
pub mod config;
pub mod http;
pub mod hub;
pub mod module;
pub mod modules;
pub mod net;
pub mod pairdb;
pub mod pulse;
pub mod server;
pub mod session;
pub mod shared;
pub mod tokens;

pub use config::Config;
pub use server::{RunningServer, start};
pub use shared::Shared;
