//! A `memfd` and its shared mapping: made by the hub (sealed against shrinking and growing, so that no process can
//! cut pages from under another's mapping and fault it), or opened from a descriptor received beside a frame.
//!
//! The crate's only `unsafe` for shared memory lives here. The bytes of a slot are read while another process may
//! write the same pages; a publisher writes a slot only between taking it and publishing it, and the hub and the
//! subscribers read it only after that, so a well-behaved publisher never races them. A misbehaving one can only
//! garble its own messages: readers copy or hand out bytes, they never trust what the bytes say.
#![allow(unsafe_code)]

use std::io;
use std::os::fd::{AsFd, AsRawFd, BorrowedFd, OwnedFd};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, RwLock};

use rustix::fs::{MemfdFlags, Mode, OFlags, SealFlags};
use rustix::mm::{MapFlags, ProtFlags};

use super::layout;

/// The address ranges of every mapping alive in this process, for [`super::is_shared`].
static MAPPED: RwLock<Vec<(usize, usize)>> = RwLock::new(Vec::new());

/// Whether `bytes` lie inside one mapping of this process.
pub(super) fn is_mapped(bytes: &[u8]) -> bool {
    let start = bytes.as_ptr() as usize;
    let end = start + bytes.len();
    let ranges = MAPPED
        .read()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    ranges.iter().any(|&(s, e)| s <= start && end <= e)
}

/// One mapped segment. Dropping it unmaps the segment and closes its descriptor; the kernel frees the memory once
/// no process maps it or holds its descriptor.
#[derive(Debug)]
pub struct Mapping {
    ptr: NonNull<u8>,
    len: usize,
    fd: OwnedFd,
    writable: bool,
}

// SAFETY: the mapping is plain shared memory, valid until `Drop`; nothing in it is tied to the thread that mapped
// it. Writes go through `write` (into a slot the writer owns by the protocol) or through atomics.
unsafe impl Send for Mapping {}
// SAFETY: as for `Send`; shared access is reads of bytes and atomic operations on the state words.
unsafe impl Sync for Mapping {}

impl Mapping {
    /// Makes a new segment of `len` bytes, zeroed, sealed at that size, mapped read-write.
    pub fn create(name: &str, len: usize) -> io::Result<Mapping> {
        let fd = rustix::fs::memfd_create(name, MemfdFlags::CLOEXEC | MemfdFlags::ALLOW_SEALING)?;
        rustix::fs::ftruncate(&fd, len as u64)?;
        rustix::fs::fcntl_add_seals(&fd, SealFlags::SHRINK | SealFlags::GROW | SealFlags::SEAL)?;
        Self::map(fd, len, true)
    }

    /// Maps a segment received from the hub. It must be at least `len` bytes long and sealed against shrinking
    /// (or a process could truncate it and make this one fault on a read).
    pub fn open(fd: OwnedFd, len: usize, writable: bool) -> io::Result<Mapping> {
        let size = rustix::fs::fstat(&fd)?.st_size;
        if u64::try_from(size).map_or(true, |s| s < len as u64) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!("shared-memory segment of {size} bytes, {len} expected"),
            ));
        }
        let seals = rustix::fs::fcntl_get_seals(&fd)?;
        if !seals.contains(SealFlags::SHRINK) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                "shared-memory segment not sealed against shrinking",
            ));
        }
        Self::map(fd, len, writable)
    }

    fn map(fd: OwnedFd, len: usize, writable: bool) -> io::Result<Mapping> {
        if len == 0 {
            return Err(io::Error::new(io::ErrorKind::InvalidInput, "empty segment"));
        }
        let prot = if writable {
            ProtFlags::READ | ProtFlags::WRITE
        } else {
            ProtFlags::READ
        };
        // SAFETY: a fresh shared mapping at an address the kernel picks, of a file at least `len` bytes long (made
        // so, or checked above, and sealed against shrinking), so every byte of it stays backed.
        let raw =
            unsafe { rustix::mm::mmap(std::ptr::null_mut(), len, prot, MapFlags::SHARED, &fd, 0)? };
        let ptr = NonNull::new(raw.cast::<u8>())
            .ok_or_else(|| io::Error::other("mmap returned a null address"))?;
        MAPPED
            .write()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push((ptr.as_ptr() as usize, ptr.as_ptr() as usize + len));
        Ok(Mapping {
            ptr,
            len,
            fd,
            writable,
        })
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The segment's descriptor (read-write where this mapping was made or opened so).
    pub fn fd(&self) -> BorrowedFd<'_> {
        self.fd.as_fd()
    }

    /// A new descriptor of the same segment that only reads: what subscribers get, so that they cannot write into
    /// anyone's messages. Opened through `/proc/self/fd`, which gives a `memfd` a fresh open file with other modes.
    pub fn read_only_fd(&self) -> io::Result<OwnedFd> {
        let path = format!("/proc/self/fd/{}", self.fd.as_raw_fd());
        Ok(rustix::fs::open(
            path.as_str(),
            OFlags::RDONLY | OFlags::CLOEXEC,
            Mode::empty(),
        )?)
    }

    /// `len` bytes from `offset`, or `None` when they are not all inside the mapping.
    pub fn bytes(&self, offset: usize, len: usize) -> Option<&[u8]> {
        let end = offset.checked_add(len)?;
        if end > self.len {
            return None;
        }
        // SAFETY: `offset..end` is inside the mapping, which lives as long as `self`; see the module's note on
        // readers and writers of the same pages.
        Some(unsafe { std::slice::from_raw_parts(self.ptr.as_ptr().add(offset), len) })
    }

    /// Copies `data` to `offset`; false when it does not fit or the mapping is read-only.
    pub fn write(&self, offset: usize, data: &[u8]) -> bool {
        let Some(end) = offset.checked_add(data.len()) else {
            return false;
        };
        if !self.writable || end > self.len {
            return false;
        }
        // SAFETY: the range is inside a writable mapping; the caller owns the slot it writes by the protocol (taken
        // by this publisher and not yet published), so no reader looks at these bytes now.
        unsafe {
            std::ptr::copy_nonoverlapping(data.as_ptr(), self.ptr.as_ptr().add(offset), data.len());
        }
        true
    }

    /// The 32-bit word at `offset`, to be touched only atomically (a release ring's counters and entries), or `None`
    /// when it is not inside the mapping or not 4-byte aligned.
    pub fn word(&self, offset: usize) -> Option<&AtomicU32> {
        if !offset.is_multiple_of(4) || offset.checked_add(4)? > self.len {
            return None;
        }
        // SAFETY: the word lies inside the mapping, which lives as long as `self`, and is 4-byte aligned (the mapping
        // starts on a page and `offset` is a multiple of 4). Every process touches it only atomically.
        Some(unsafe { AtomicU32::from_ptr(self.ptr.as_ptr().add(offset).cast::<u32>()) })
    }

    /// The state word of `slot` (see [`layout`]), or `None` outside the states.
    pub fn state(&self, slots: u32, slot: u32) -> Option<&AtomicU32> {
        if slot >= slots || layout::data_offset(slots) > self.len {
            return None;
        }
        // The states end before slot 0 begins, at 64 + 4 * slot: `word` checks the bounds and the alignment again.
        self.word(layout::state_offset(slot))
    }
}

/// A slot taken for writing (its state word turned from free to taken): the one place that may write it until it is
/// published or dropped. Dropping it unpublished frees the slot again.
#[derive(Debug)]
pub struct SlotMut {
    map: Arc<Mapping>,
    slots: u32,
    slot: u32,
    offset: usize,
    len: usize,
    /// Published: the hub frees the slot from now on.
    handed_over: bool,
}

impl Mapping {
    /// Takes `slot` (free -> taken) to write `len` bytes into it; `None` when it is held, out of bounds, longer than
    /// a slot, or the mapping is read-only.
    pub fn take_slot(
        self: &Arc<Self>,
        slots: u32,
        slot_size: u32,
        slot: u32,
        len: usize,
    ) -> Option<SlotMut> {
        if !self.writable || len > slot_size as usize {
            return None;
        }
        let offset = layout::slot_offset(slots, slot_size, slot);
        self.bytes(offset, len)?;
        let state = self.state(slots, slot)?;
        state
            .compare_exchange(
                layout::FREE,
                layout::TAKEN,
                Ordering::Acquire,
                Ordering::Relaxed,
            )
            .ok()?;
        Some(SlotMut {
            map: self.clone(),
            slots,
            slot,
            offset,
            len,
            handed_over: false,
        })
    }
}

impl SlotMut {
    pub fn slot(&self) -> u32 {
        self.slot
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The slot's bytes to write the message into.
    pub fn as_mut_slice(&mut self) -> &mut [u8] {
        // SAFETY: the range is inside a writable mapping (checked in `take_slot`), and this `SlotMut` is its only
        // writer: the compare-exchange from free to taken succeeded here, no other process writes a taken slot, and
        // nobody reads it before it is published, which consumes `self`.
        unsafe { std::slice::from_raw_parts_mut(self.map.ptr.as_ptr().add(self.offset), self.len) }
    }

    /// Shortens the message to `len` bytes (a frame encoded into a slot of its largest size).
    pub fn truncate(&mut self, len: usize) {
        self.len = self.len.min(len);
    }

    /// The slot is published: from now on the hub frees it.
    pub fn hand_over(mut self) -> (u32, usize) {
        self.handed_over = true;
        (self.slot, self.len)
    }
}

impl Drop for SlotMut {
    fn drop(&mut self) {
        if !self.handed_over
            && let Some(state) = self.map.state(self.slots, self.slot)
        {
            state.store(layout::FREE, Ordering::Release);
        }
    }
}

impl Drop for Mapping {
    fn drop(&mut self) {
        let start = self.ptr.as_ptr() as usize;
        MAPPED
            .write()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .retain(|&(s, _)| s != start);
        // SAFETY: the range was mapped in `map` and nothing borrows from it any more: views hold the `Mapping`
        // alive through an `Arc`, so this runs after the last one is gone.
        let _ = unsafe { rustix::mm::munmap(self.ptr.as_ptr().cast(), self.len) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_segment_reopened_read_only_sees_what_the_writer_wrote() {
        let len = layout::segment_len(4, 4096);
        let rw = Mapping::create("flow-shm-test", len).expect("create");
        let off = layout::slot_offset(4, 4096, 2);
        assert!(rw.write(off, b"hello"));
        rw.state(4, 2)
            .expect("state")
            .store(layout::TAKEN, Ordering::Release);
        let ro = Mapping::open(rw.read_only_fd().expect("reopen"), len, false).expect("open");
        assert_eq!(ro.bytes(off, 5), Some(&b"hello"[..]));
        assert_eq!(
            ro.state(4, 2).expect("state").load(Ordering::Acquire),
            layout::TAKEN
        );
        assert!(!ro.write(off, b"x"), "a read-only mapping refuses writes");
        assert!(super::super::is_shared(ro.bytes(off, 5).expect("bytes")));
        assert!(!super::super::is_shared(b"elsewhere"));
        assert!(ro.bytes(len - 1, 2).is_none());
        assert!(ro.state(4, 4).is_none());
    }

    #[test]
    fn a_taken_slot_is_written_once_and_freed_unless_handed_over() {
        let len = layout::segment_len(2, 4096);
        let map = Arc::new(Mapping::create("flow-shm-test", len).expect("create"));
        let mut slot = map.take_slot(2, 4096, 1, 3).expect("free");
        assert!(map.take_slot(2, 4096, 1, 3).is_none(), "taken once");
        slot.as_mut_slice().copy_from_slice(b"abc");
        drop(slot);
        let again = map.take_slot(2, 4096, 1, 3).expect("freed by the drop");
        assert_eq!(again.hand_over(), (1, 3));
        assert!(
            map.take_slot(2, 4096, 1, 3).is_none(),
            "handed over: the hub frees it"
        );
        assert!(
            map.take_slot(2, 4096, 0, 4097).is_none(),
            "longer than a slot"
        );
        let off = layout::slot_offset(2, 4096, 1);
        assert_eq!(map.bytes(off, 3), Some(&b"abc"[..]));
    }

    #[test]
    fn a_segment_cannot_be_shrunk_or_opened_short() {
        let len = layout::segment_len(1, 4096);
        let rw = Mapping::create("flow-shm-test", len).expect("create");
        assert!(
            rustix::fs::ftruncate(rw.fd(), 10).is_err(),
            "sealed against shrinking"
        );
        let fd = rw.read_only_fd().expect("reopen");
        assert!(Mapping::open(fd, len + 4096, false).is_err());
    }
}
