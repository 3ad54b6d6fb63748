//! A slot as a [`Bytes`]: zero-copy and read-only for whoever gets it, and given back when its last clone goes.

use std::sync::Arc;

use bytes::Bytes;

use super::mapping::Mapping;

/// Who gets a slot back once nobody holds its message: the hub (which frees it for the publisher) or a client
/// (which tells the hub it is done).
pub trait SlotOwner: Send + Sync + std::fmt::Debug + 'static {
    fn release(&self, slot: u32);
}

/// The owner of a slot's bytes inside a [`Bytes`].
#[derive(Debug)]
struct SlotView {
    map: Arc<Mapping>,
    offset: usize,
    len: usize,
    slot: u32,
    owner: Arc<dyn SlotOwner>,
}

impl AsRef<[u8]> for SlotView {
    fn as_ref(&self) -> &[u8] {
        // Checked in `slot_bytes`, and a mapping never changes its length.
        self.map.bytes(self.offset, self.len).unwrap_or_default()
    }
}

impl Drop for SlotView {
    fn drop(&mut self) {
        self.owner.release(self.slot);
    }
}

/// The `len` bytes at `offset` of `map` as one shared buffer; `owner.release(slot)` runs when its last clone is
/// dropped. `None` (and nothing released) when the range is not inside the mapping.
pub fn slot_bytes(
    map: Arc<Mapping>,
    offset: usize,
    len: usize,
    slot: u32,
    owner: Arc<dyn SlotOwner>,
) -> Option<Bytes> {
    map.bytes(offset, len)?;
    Some(Bytes::from_owner(SlotView {
        map,
        offset,
        len,
        slot,
        owner,
    }))
}
