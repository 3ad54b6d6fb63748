//! Per-face analysis on the faces a detector found: dlib's 68 landmarks and what they say (mouth and eye
//! openness, head yaw and pitch, a smile degree), and dlib's ResNet descriptor for who the face is.
//!
//! The models are dlib's, from the `face-recognition-models` package (`make model-face`, checked against
//! config/models.sha256); the library is Debian's `libdlib-dev`, called through one small C++ file
//! (`cpp/dlib_face.cpp`) and one FFI module ([`ffi`](crate::ffi) is private). Nothing here knows OpenCV: a frame is a
//! borrowed grey buffer ([`GreyImage`]).

mod analyzer;
mod error;
mod ffi;
mod grey;
pub mod identity;
pub mod landmarks;
pub mod measures;

pub use analyzer::{DEFAULT_DESCRIPTOR, DEFAULT_LANDMARKS, FaceAnalyzer, FaceBox, FaceModelPaths};
pub use error::{FaceError, MAKE_TARGET};
pub use grey::GreyImage;
pub use identity::{Acquaintance, Descriptor, SAME_PERSON_DISTANCE, recognise};
pub use landmarks::{LANDMARKS, Landmarks, Point};
pub use measures::{FaceMeasures, LOOKING_WITHIN_DEG, SMILING_FROM, measure};
