//! FlowProtocol for boards without an operating system: `no_std`, no allocator, every buffer the caller's.
//!
//! - [`line`]: the framing of a serial line (COBS around a CRC-32), shared with the hub and the SDK, which wrap it
//!   in their serial transport: a damaged packet is dropped and counted, the next one is read.
//! - [`crc`]: the CRC-32 the framing carries.
//! - [`frame`]: FlowProtocol frame boundaries (`len | op | req | body`), a pure `check` / `parse` over bytes.
//! - [`message`]: the commands a board sends and the events it reads, borrowing their strings and payloads; the
//!   opcodes and layouts of `flow::protocol` (docs/protocol.md).
//! - [`codec`]: commands encoded into a caller's slice, events decoded from borrowed bytes; unknown events skip.
//! - [`client`]: a blocking client over a caller's [`client::Link`] (a UART, a pseudo-terminal): login, channels,
//!   publish, subscribe, call, poll, in two caller buffers.
#![no_std]

pub mod client;
pub mod codec;
pub mod crc;
pub mod frame;
pub mod line;
pub mod message;

pub use client::{Client, Link};
