//! The layout of a shared-memory segment, as pure arithmetic over its slot count and size.
//!
//! ```text
//! offset 0                 magic:u32 = "FSHM" | slots:u32 | slot_size:u32 | 52 bytes reserved
//! offset 64                state:u32 * slots   (0 free, 1 taken by the publisher; little-endian atomics)
//! offset data_offset(n)    slot 0 | slot 1 | ... | slot n-1     (each slot_size bytes, page aligned)
//! ```
//!
//! Only the publisher sets a state to taken, and only the hub sets it free again (once nobody holds the message);
//! subscribers map the segment read-only and never look at the states.

/// The first word of a segment.
pub const MAGIC: u32 = u32::from_le_bytes(*b"FSHM");
/// Where the slot states begin.
pub const STATES_OFFSET: usize = 64;
/// Pages are the unit of mapping; slots start on one.
pub const PAGE: usize = 4096;
/// A slot nobody holds.
pub const FREE: u32 = 0;
/// A slot the publisher has taken to write a message into (until the hub frees it).
pub const TAKEN: u32 = 1;
/// The most slots a segment has.
pub const MAX_SLOTS: u32 = 4096;
/// The smallest and the largest slot.
pub const MIN_SLOT: u32 = PAGE as u32;
pub const MAX_SLOT: u32 = 1 << 30;
/// The largest segment (slots and header): 4 GiB of address space, of which only the pages written are memory.
pub const MAX_SEGMENT: u64 = 1 << 32;

/// Where slot 0 begins: after the header and the states, on a page boundary.
pub fn data_offset(slots: u32) -> usize {
    round_up(STATES_OFFSET + 4 * slots as usize, PAGE)
}

/// Where slot `slot`'s state word lies.
pub fn state_offset(slot: u32) -> usize {
    STATES_OFFSET + 4 * slot as usize
}

/// Where slot `slot` begins.
pub fn slot_offset(slots: u32, slot_size: u32, slot: u32) -> usize {
    data_offset(slots) + slot as usize * slot_size as usize
}

/// The whole segment's length.
pub fn segment_len(slots: u32, slot_size: u32) -> usize {
    data_offset(slots) + slots as usize * slot_size as usize
}

/// The slot size for a message of `len` bytes: the next power of two, at least a page, so that a stream whose
/// messages vary a little (camera JPEGs) keeps one segment.
pub fn slot_size_for(len: usize) -> Option<u32> {
    let size = len.max(MIN_SLOT as usize).checked_next_power_of_two()?;
    u32::try_from(size).ok().filter(|s| *s <= MAX_SLOT)
}

/// Why a segment's shape is refused, if it is.
pub fn check_shape(slots: u32, slot_size: u32) -> Result<(), String> {
    if slots == 0 || slots > MAX_SLOTS {
        return Err(format!("{slots} slots (1 ..= {MAX_SLOTS})"));
    }
    if !(MIN_SLOT..=MAX_SLOT).contains(&slot_size) || !(slot_size as usize).is_multiple_of(PAGE) {
        return Err(format!(
            "slot size {slot_size} (a multiple of {PAGE} in {MIN_SLOT} ..= {MAX_SLOT})"
        ));
    }
    if segment_len(slots, slot_size) as u64 > MAX_SEGMENT {
        return Err(format!(
            "{slots} slots of {slot_size} bytes exceed {MAX_SEGMENT} bytes"
        ));
    }
    Ok(())
}

fn round_up(n: usize, to: usize) -> usize {
    n.div_ceil(to) * to
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_begin_on_pages_after_the_states() {
        assert_eq!(data_offset(1), PAGE);
        assert_eq!(data_offset(1008), PAGE);
        assert_eq!(data_offset(1009), 2 * PAGE);
        assert_eq!(slot_offset(64, 8192, 3), PAGE + 3 * 8192);
        assert_eq!(segment_len(64, 8192), PAGE + 64 * 8192);
        assert_eq!(state_offset(2), 72);
    }

    #[test]
    fn slot_sizes_are_powers_of_two_of_at_least_a_page() {
        assert_eq!(slot_size_for(0), Some(4096));
        assert_eq!(slot_size_for(4097), Some(8192));
        assert_eq!(slot_size_for(52_000), Some(65_536));
        assert_eq!(slot_size_for(1 << 20), Some(1 << 20));
        assert_eq!(slot_size_for((1 << 30) + 1), None);
    }

    #[test]
    fn shapes_out_of_bounds_are_refused() {
        assert!(check_shape(64, 65_536).is_ok());
        assert!(check_shape(0, 65_536).is_err());
        assert!(check_shape(MAX_SLOTS + 1, 4096).is_err());
        assert!(check_shape(4, 5000).is_err());
        assert!(check_shape(4096, 1 << 30).is_err());
    }
}
