//! The face analyser: the models loaded once, then landmarks and descriptors for faces found by a detector.

use std::path::{Path, PathBuf};

use crate::error::FaceError;
use crate::ffi::Models;
use crate::grey::GreyImage;
use crate::identity::Descriptor;
use crate::landmarks::Landmarks;

/// Where the models are; the defaults are where `make model-face` puts them in the repository this was built
/// from (an installed agent names its copies in its configuration).
#[derive(Debug, Clone, PartialEq)]
pub struct FaceModelPaths {
    /// dlib's 68-point shape predictor.
    pub landmarks: PathBuf,
    /// dlib's ResNet face descriptor; `None` leaves identities out.
    pub descriptor: Option<PathBuf>,
}

impl Default for FaceModelPaths {
    fn default() -> Self {
        let root = repo_root();
        Self {
            landmarks: root.join(DEFAULT_LANDMARKS),
            descriptor: Some(root.join(DEFAULT_DESCRIPTOR)),
        }
    }
}

/// The repository root, found from this crate's manifest directory (agent/face).
fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// The models' places in the repository.
pub const DEFAULT_LANDMARKS: &str = "models/dlib/shape_predictor_68_face_landmarks.dat";
pub const DEFAULT_DESCRIPTOR: &str = "models/dlib/dlib_face_recognition_resnet_model_v1.dat";

impl FaceModelPaths {
    /// Fails naming the first file that is not there, and the make target that provisions it.
    pub fn check(&self) -> Result<(), FaceError> {
        let present = |path: &Path| {
            if path.is_file() {
                Ok(())
            } else {
                Err(FaceError::Missing {
                    path: path.to_path_buf(),
                })
            }
        };
        present(&self.landmarks)?;
        if let Some(descriptor) = &self.descriptor {
            present(descriptor)?;
        }
        Ok(())
    }
}

/// A face box in frame pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FaceBox {
    pub x: i32,
    pub y: i32,
    pub width: i32,
    pub height: i32,
}

/// The loaded models; one per thread that analyses faces.
#[derive(Debug)]
pub struct FaceAnalyzer {
    models: Models,
    descriptors: bool,
}

impl FaceAnalyzer {
    /// Loads the models (about 0.7 s for both); a missing or unreadable file fails naming it.
    pub fn load(paths: &FaceModelPaths) -> Result<Self, FaceError> {
        paths.check()?;
        let models = Models::load(&paths.landmarks, paths.descriptor.as_deref()).map_err(|e| {
            match (e, &paths.descriptor) {
                // The C side cannot tell which file failed; dlib's message names the object it was reading.
                (FaceError::Load { reason, .. }, Some(descriptor))
                    if reason.contains("net") || reason.contains("loss_metric") =>
                {
                    FaceError::Load {
                        path: descriptor.clone(),
                        reason,
                    }
                }
                (e, _) => e,
            }
        })?;
        Ok(Self {
            models,
            descriptors: paths.descriptor.is_some(),
        })
    }

    /// Whether [`FaceAnalyzer::descriptor`] can run.
    pub fn has_descriptors(&self) -> bool {
        self.descriptors
    }

    /// The 68 points of the face in `face`.
    pub fn landmarks(&self, image: &GreyImage<'_>, face: FaceBox) -> Result<Landmarks, FaceError> {
        self.models
            .landmarks(image, [face.x, face.y, face.width, face.height])
    }

    /// The identity descriptor of a face with these points (about 15 ms on one core).
    pub fn descriptor(
        &mut self,
        image: &GreyImage<'_>,
        landmarks: &Landmarks,
    ) -> Result<Descriptor, FaceError> {
        self.models.descriptor(image, landmarks).map(Descriptor)
    }
}
