//! The one module that calls the C++ face of dlib (`cpp/dlib_face.cpp`): loading the two models, and running them
//! on a borrowed grey frame. Everything else in the crate is safe Rust over [`Models`].

// The workspace denies `unsafe_code`; this module is the FFI boundary to dlib and needs it. Every block states why
// it is sound.
#![allow(unsafe_code)]

use std::ffi::{CString, c_char};
use std::path::Path;
use std::ptr::NonNull;

use crate::error::FaceError;
use crate::grey::GreyImage;
use crate::landmarks::{LANDMARKS, Landmarks};

/// Room for dlib's error messages (deserialisation errors name the object and the file's problem).
const ERROR_BYTES: usize = 512;

#[repr(C)]
struct RawModels {
    _private: [u8; 0],
}

unsafe extern "C" {
    fn face_models_load(
        landmarks_path: *const c_char,
        descriptor_path: *const c_char,
        err: *mut c_char,
        err_len: usize,
    ) -> *mut RawModels;
    fn face_models_free(models: *mut RawModels);
    fn face_landmarks(
        models: *const RawModels,
        pixels: *const u8,
        width: i32,
        height: i32,
        stride: i32,
        x: i32,
        y: i32,
        w: i32,
        h: i32,
        out_xy: *mut f32,
        err: *mut c_char,
        err_len: usize,
    ) -> i32;
    fn face_descriptor(
        models: *mut RawModels,
        pixels: *const u8,
        width: i32,
        height: i32,
        stride: i32,
        xy: *const f32,
        out: *mut f32,
        err: *mut c_char,
        err_len: usize,
    ) -> i32;
}

/// dlib's loaded models: the 68-point shape predictor, and the descriptor network when one was asked for.
#[derive(Debug)]
pub(crate) struct Models {
    raw: NonNull<RawModels>,
}

// SAFETY: the C++ objects behind the pointer hold no thread-local state and no references to other objects; they
// may be used from whichever thread owns the `Models`. `Models` is not `Sync` (the descriptor network keeps scratch
// tensors that each call overwrites), and `&mut self` on `descriptor` keeps one call at a time.
unsafe impl Send for Models {}

impl Models {
    pub(crate) fn load(landmarks: &Path, descriptor: Option<&Path>) -> Result<Models, FaceError> {
        let c_path = |path: &Path| {
            CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| FaceError::Load {
                path: path.to_path_buf(),
                reason: "the path contains a NUL byte".into(),
            })
        };
        let landmarks_c = c_path(landmarks)?;
        let descriptor_c = descriptor.map(c_path).transpose()?;
        let mut err = [0 as c_char; ERROR_BYTES];
        // SAFETY: both paths are NUL-terminated strings that outlive the call (the descriptor's may be null, which
        // the C side reads as "none"); `err` is a writable buffer of `ERROR_BYTES` that the C side NUL-terminates.
        let raw = unsafe {
            face_models_load(
                landmarks_c.as_ptr(),
                descriptor_c
                    .as_ref()
                    .map_or(std::ptr::null(), |path| path.as_ptr()),
                err.as_mut_ptr(),
                ERROR_BYTES,
            )
        };
        NonNull::new(raw)
            .map(|raw| Models { raw })
            .ok_or_else(|| FaceError::Load {
                path: landmarks.to_path_buf(),
                reason: message(&err),
            })
    }

    /// The 68 landmarks of the face in `face` (x, y, width, height in frame pixels).
    pub(crate) fn landmarks(
        &self,
        image: &GreyImage<'_>,
        face: [i32; 4],
    ) -> Result<Landmarks, FaceError> {
        let mut xy = [0f32; 2 * LANDMARKS];
        let mut err = [0 as c_char; ERROR_BYTES];
        // SAFETY: `self.raw` is a live model set from `face_models_load` (freed only in `drop`); `image` has checked
        // that its pixel slice holds `height` rows of `stride` bytes with `width <= stride`, which is all the C side
        // reads; `xy` has room for the 68 points it writes, and `err` for its message.
        let status = unsafe {
            face_landmarks(
                self.raw.as_ptr(),
                image.pixels().as_ptr(),
                image.width(),
                image.height(),
                image.stride(),
                face[0],
                face[1],
                face[2],
                face[3],
                xy.as_mut_ptr(),
                err.as_mut_ptr(),
                ERROR_BYTES,
            )
        };
        if status != 0 {
            return Err(FaceError::Run(message(&err)));
        }
        Ok(Landmarks::from_xy(&xy))
    }

    /// The 128-number descriptor of the face whose landmarks are `landmarks`.
    pub(crate) fn descriptor(
        &mut self,
        image: &GreyImage<'_>,
        landmarks: &Landmarks,
    ) -> Result<[f32; 128], FaceError> {
        let xy = landmarks.to_xy();
        let mut out = [0f32; 128];
        let mut err = [0 as c_char; ERROR_BYTES];
        // SAFETY: as in `landmarks`; `xy` holds the 68 points the C side reads and `out` the 128 numbers it writes;
        // `&mut self` keeps any other call off the network while it runs.
        let status = unsafe {
            face_descriptor(
                self.raw.as_ptr(),
                image.pixels().as_ptr(),
                image.width(),
                image.height(),
                image.stride(),
                xy.as_ptr(),
                out.as_mut_ptr(),
                err.as_mut_ptr(),
                ERROR_BYTES,
            )
        };
        if status != 0 {
            return Err(FaceError::Run(message(&err)));
        }
        Ok(out)
    }
}

impl Drop for Models {
    fn drop(&mut self) {
        // SAFETY: `raw` came from `face_models_load` and is freed once, here.
        unsafe { face_models_free(self.raw.as_ptr()) }
    }
}

/// The NUL-terminated message the C side wrote.
fn message(err: &[c_char]) -> String {
    let bytes: Vec<u8> = err
        .iter()
        .take_while(|&&c| c != 0)
        .map(|&c| c as u8)
        .collect();
    let text = String::from_utf8_lossy(&bytes).trim().to_owned();
    if text.is_empty() {
        "dlib gave no reason".into()
    } else {
        text
    }
}
