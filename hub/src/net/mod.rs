//! Network edges: the connection driver shared by every transport, and one
//! listener module per transport.

pub mod conn;
pub mod descriptors;
pub mod io_runtime;
pub mod serial;
pub mod shm_writer;
pub mod tcp;
pub mod udp;
pub mod unix;
pub mod ws;

pub use conn::{PRE_LOGIN_MAX_FRAME, serve_connection};
pub use io_runtime::IoRuntime;
