//! The flow hub (SkRobot's FlowNetwork): named channels (1:N streams, 1:1 services), the persisted pair database,
//! FastTick / SlowTick / OneSecTick pulses, the transports (TCP, Unix socket, WebSocket), the HTTP edge with its
//! access gate, and the host of in-server modules. It links none of OpenCV, espeak-ng or Whisper: an application
//! (`robot-agent`) brings its modules and routes through [`server::Application`]. See ARCHITECTURE.md.

pub mod admission;
pub mod cli;
pub mod config;
pub mod doctor;
pub mod federation;
pub mod http;
pub mod hub;
pub mod log;
pub mod metrics;
pub mod module;
pub mod net;
pub mod pairdb;
pub mod pulse;
pub mod server;
pub mod session;
pub mod shared;
pub mod tokens;
pub mod zenoh_names;

pub use config::Config;
pub use server::{Application, RunningServer, start};
pub use shared::Shared;

#[cfg(test)]
mod shm_tests;
#[cfg(test)]
mod shutdown_tests;
