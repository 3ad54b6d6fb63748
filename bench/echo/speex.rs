//! Speex's echo canceller (Debian's `libspeexdsp`), echo-bench's baseline: the bench's one FFI module.
#![allow(unsafe_code)]

use std::os::raw::{c_int, c_void};
use std::ptr::NonNull;

/// `SpeexEchoState`, opaque.
#[repr(C)]
struct SpeexEchoState {
    _private: [u8; 0],
}

#[link(name = "speexdsp")]
unsafe extern "C" {
    fn speex_echo_state_init(frame_size: c_int, filter_length: c_int) -> *mut SpeexEchoState;
    fn speex_echo_state_destroy(st: *mut SpeexEchoState);
    fn speex_echo_cancellation(
        st: *mut SpeexEchoState,
        rec: *const i16,
        play: *const i16,
        out: *mut i16,
    );
    fn speex_echo_ctl(st: *mut SpeexEchoState, request: c_int, ptr: *mut c_void) -> c_int;
}

/// `SPEEX_ECHO_SET_SAMPLING_RATE` (speex_echo.h).
const SET_SAMPLING_RATE: c_int = 24;

/// One Speex echo canceller.
#[derive(Debug)]
pub struct SpeexEcho {
    state: NonNull<SpeexEchoState>,
    frame: usize,
}

impl SpeexEcho {
    /// A canceller of `frame` samples a call with a filter `filter` samples long, at `rate` Hz.
    pub fn new(frame: usize, filter: usize, rate: u32) -> anyhow::Result<Self> {
        let (Ok(frame_c), Ok(filter_c), Ok(mut rate_c)) = (
            c_int::try_from(frame),
            c_int::try_from(filter),
            c_int::try_from(rate),
        ) else {
            anyhow::bail!("speex: sizes out of range");
        };
        // SAFETY: plain values in; the library allocates and returns its state or null.
        let raw = unsafe { speex_echo_state_init(frame_c, filter_c) };
        let state =
            NonNull::new(raw).ok_or_else(|| anyhow::anyhow!("speex_echo_state_init failed"))?;
        // SAFETY: `state` is the live state just made; the request reads one c_int through the pointer.
        unsafe {
            speex_echo_ctl(
                state.as_ptr(),
                SET_SAMPLING_RATE,
                (&raw mut rate_c).cast::<c_void>(),
            )
        };
        Ok(Self { state, frame })
    }

    /// Cancels `play`'s echo from `rec` into `out`, each exactly one frame.
    pub fn cancel(&mut self, rec: &[i16], play: &[i16], out: &mut [i16]) {
        assert!(rec.len() == self.frame && play.len() == self.frame && out.len() == self.frame);
        // SAFETY: the state is live; the three buffers hold exactly the frame size the state was made with, which
        // is all the library reads or writes.
        unsafe {
            speex_echo_cancellation(
                self.state.as_ptr(),
                rec.as_ptr(),
                play.as_ptr(),
                out.as_mut_ptr(),
            )
        };
    }
}

impl Drop for SpeexEcho {
    fn drop(&mut self) {
        // SAFETY: the state was made by speex_echo_state_init and is destroyed once, here.
        unsafe { speex_echo_state_destroy(self.state.as_ptr()) };
    }
}
