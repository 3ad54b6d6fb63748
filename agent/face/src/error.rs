//! What can go wrong when loading or running the face models.

use std::path::PathBuf;

/// The make target that provisions the models, named in every error about a model file.
pub const MAKE_TARGET: &str = "make model-face";

#[derive(Debug, thiserror::Error)]
pub enum FaceError {
    #[error("face model {} is missing (run `{MAKE_TARGET}`)", path.display())]
    Missing { path: PathBuf },
    #[error("face model {} cannot be loaded: {reason} (run `{MAKE_TARGET}` to provision it again)", path.display())]
    Load { path: PathBuf, reason: String },
    #[error("grey image: {0}")]
    Image(String),
    #[error("dlib: {0}")]
    Run(String),
}
