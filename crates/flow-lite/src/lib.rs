//! FlowProtocol for boards without an operating system: `no_std`, no allocator, every buffer the caller's.
//!
//! - [`line`]: the framing of a serial line (COBS around a CRC-32), shared with the hub and the SDK, which wrap it
//!   in their serial transport: a damaged packet is dropped and counted, the next one is read.
//! - [`crc`]: the CRC-32 the framing carries.
#![no_std]

pub mod crc;
pub mod line;
