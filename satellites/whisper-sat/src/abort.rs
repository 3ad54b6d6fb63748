//! Stopping a whisper.cpp inference early: the abort callback of `whisper_full_params`, answered from a flag that
//! another thread sets.
//!
//! whisper.cpp (1.8.3) asks the callback once the encoder has run and after every decoder step (one token), and
//! gives up (an inference error) when it says yes, so a satellite whose speculative transcription became useless
//! gets its cores back after the encoder and at most one token instead of after the whole decode. The encoder
//! itself cannot be stopped: its scheduler never asks (measured with tiny.en on two cores, an abort saves the
//! decoding, about a quarter of a short utterance's inference). whisper-rs has a safe setter for a closure, but it
//! never frees the boxed closure (one small leak per decode for the satellite's whole life); the raw setter needs
//! `unsafe`, which is kept to this module: the callback only reads an `AtomicBool` that the borrow checker keeps
//! alive for as long as the parameters can be used.

#![allow(unsafe_code)]

use std::ffi::c_void;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use whisper_rs::FullParams;

/// A flag shared between the thread that runs an inference and one that may want it stopped.
#[derive(Debug, Clone, Default)]
pub struct AbortFlag(Arc<AtomicBool>);

impl AbortFlag {
    /// A flag that is not set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks every inference this flag is attached to to stop as soon as it can.
    pub fn abort(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// True once `abort` was called.
    pub fn is_aborted(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }

    /// Makes inference with `params` stop when this flag is set. The flag is borrowed for the parameters' lifetime,
    /// so it outlives every inference that can run with them.
    pub fn attach<'a>(&'a self, params: &mut FullParams<'a, '_>) {
        let flag: &'a AtomicBool = &self.0;
        // SAFETY: `aborted` only reads the `AtomicBool` behind the user-data pointer, which points into the `Arc`
        // borrowed for `'a`, as long as `params` may be used; whisper.cpp calls the callback only during
        // `whisper_full` with these parameters and never writes through the pointer. Reading an atomic from the
        // inference threads while another thread stores to it is sound.
        unsafe {
            params.set_abort_callback(Some(aborted));
            params
                .set_abort_callback_user_data(std::ptr::from_ref(flag).cast_mut().cast::<c_void>());
        }
    }
}

/// whisper.cpp's abort callback: true when the flag behind `user_data` is set.
unsafe extern "C" fn aborted(user_data: *mut c_void) -> bool {
    if user_data.is_null() {
        return false;
    }
    // SAFETY: `AbortFlag::attach` is the only place this callback is installed, always with a pointer to an
    // `AtomicBool` that lives as long as the parameters (see there); it is only read here.
    let flag = unsafe { &*user_data.cast::<AtomicBool>() };
    flag.load(Ordering::Relaxed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_callback_reads_the_flag_it_was_attached_with() {
        let flag = AbortFlag::new();
        let pointer = std::ptr::from_ref::<AtomicBool>(&flag.0)
            .cast_mut()
            .cast::<c_void>();
        // SAFETY: the pointer is to the flag's live `AtomicBool`, as `attach` passes it.
        assert!(!unsafe { aborted(pointer) });
        flag.clone().abort();
        assert!(flag.is_aborted());
        // SAFETY: as above.
        assert!(unsafe { aborted(pointer) });
        // SAFETY: a null pointer is answered without reading anything.
        assert!(!unsafe { aborted(std::ptr::null_mut()) });
    }
}
