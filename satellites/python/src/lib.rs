//! `flow._native`: the Python binding of the Rust `flow` SDK. Python satellites speak FlowProtocol through the very
//! code Rust satellites use; nothing here encodes a frame.
//!
//! - [`runtime`]: the one tokio runtime of the process and the wait that releases the GIL and lets Ctrl-C through.
//! - [`errors`]: the `FlowError` exception hierarchy and the mapping from [`flow::FlowError`].
//! - [`client`]: `Client` (connect, channels, calls), with [`publisher`] (and [`loan`], a message written in place), [`subscription`], [`service`] and
//!   [`database`] for what it hands out, and [`message`] for what arrives; [`header`] reads the channel headers
//!   both `Client` and `Publisher` take.
//! - [`events`]: the pulses and messages of a `Sketch`, merged in Rust.
//! - [`contract`]: the agent's channels and message shapes from the contract crate.

use pyo3::prelude::*;

mod client;
mod contract;
mod database;
mod errors;
mod events;
mod header;
mod loan;
mod message;
mod payload;
mod publisher;
mod runtime;
mod service;
mod subscription;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    runtime::start()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<client::Client>()?;
    m.add_class::<publisher::Publisher>()?;
    m.add_class::<loan::Loan>()?;
    m.add_class::<subscription::Subscription>()?;
    m.add_class::<service::Service>()?;
    m.add_class::<database::Database>()?;
    m.add_class::<message::Message>()?;
    m.add_class::<events::Events>()?;
    errors::register(m)?;
    contract::register(m)?;
    Ok(())
}
