//! Shared memory between the hub and the clients on its machine: segments the hub makes (a `memfd`, sealed against
//! resizing), handed over a Unix socket beside a frame (`SCM_RIGHTS`), and messages that travel as slot references.
//!
//! - `layout.rs`: where the slot states and the slots lie in a segment (pure arithmetic, the one place that knows);
//! - `mapping.rs`: the `memfd` and its mapping, the only `unsafe` of the crate's shared memory;
//! - `fdpass.rs`: sending and receiving a descriptor beside the bytes of a Unix stream;
//! - `view.rs`: a slot as a [`bytes::Bytes`] that gives the slot back when its last clone is dropped;
//! - `ring.rs`: the release ring, where a subscriber gives slots back without a frame each.
//!
//! The protocol (`docs/protocol.md`, "Shared memory"): a client on the Unix socket sends `ShmAccept` after login;
//! from then on a payload at or above the hub's threshold may reach it as `DataRef`, into a segment introduced once by
//! `Segment` with a read-only descriptor. A publisher asks `ShmOpen` for a segment of its channel, writes a message
//! into a free slot and sends `PublishRef`; the hub marks the slot free again in the segment's header once no queue,
//! subscriber or recorder holds the message any more. Everything about a segment dies with the processes that map
//! it: a `memfd` has no name in `/dev/shm` that could outlive them.

pub mod fdpass;
pub mod layout;
mod mapping;
pub mod ring;
mod view;

pub use mapping::{Mapping, SlotMut};
pub use view::{SlotOwner, slot_bytes};

/// Whether `bytes` lie inside a shared-memory segment this process maps: how a program (or a test) tells that a
/// payload came by reference, without a copy.
pub fn is_shared(bytes: &[u8]) -> bool {
    mapping::is_mapped(bytes)
}
