//! Checking a model file against `config/models.sha256` before it is loaded, so that a missing or damaged voice
//! stops the agent at start with the path, the checksums and the command that provisions it.

use std::io::Read;
use std::path::Path;

use sha2::{Digest, Sha256};

use crate::error::VoiceError;

/// The repository's checksum list (sha256sum format, paths relative to the repository root), built in so that a
/// binary started from anywhere knows what its model files must be.
const MODELS_SHA256: &str = include_str!("../../../config/models.sha256");

/// The `make` target that provisions the Piper voice and ONNX Runtime.
pub const MAKE_TARGET: &str = "make model-voice";

/// The checksum `config/models.sha256` lists for `path`: the entry whose repository-relative path ends `path`
/// (an absolute path into a checkout, or the relative path itself).
pub fn listed_sha256(path: &Path) -> Option<&'static str> {
    let text = path.to_string_lossy();
    MODELS_SHA256.lines().find_map(|line| {
        let (sum, listed) = line.split_once("  ")?;
        let listed = listed.trim();
        let matches = text == listed
            || text
                .strip_suffix(listed)
                .is_some_and(|head| head.ends_with('/'));
        matches.then_some(sum.trim())
    })
}

/// The sha256 of a file, in lower-case hex.
pub fn file_sha256(path: &Path) -> std::io::Result<String> {
    let mut file = std::fs::File::open(path)?;
    let mut hasher = Sha256::new();
    let mut buffer = vec![0u8; 1 << 20];
    loop {
        let read = file.read(&mut buffer)?;
        if read == 0 {
            break;
        }
        hasher.update(&buffer[..read]);
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|byte| format!("{byte:02x}"))
        .collect())
}

/// Checks that `path` exists and has the checksum `expected` (or, when `None`, the one `config/models.sha256`
/// lists for it). `what` names the file in the error ("Piper voice", "ONNX Runtime").
pub fn verify(path: &Path, expected: Option<&str>, what: &'static str) -> Result<(), VoiceError> {
    let expected = match expected.or_else(|| listed_sha256(path)) {
        Some(sum) => sum.to_owned(),
        None => {
            return Err(VoiceError::ModelFile {
                what,
                path: path.to_path_buf(),
                problem: "config/models.sha256 lists no checksum for it".into(),
                expected: "none".into(),
            });
        }
    };
    let problem = match file_sha256(path) {
        Ok(actual) if actual.eq_ignore_ascii_case(&expected) => return Ok(()),
        Ok(actual) => format!("its sha256 is {actual}"),
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => "the file is missing".into(),
        Err(error) => format!("it cannot be read: {error}"),
    };
    Err(VoiceError::ModelFile {
        what,
        path: path.to_path_buf(),
        problem,
        expected,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn listed_paths_are_found_relative_or_inside_a_checkout() {
        let relative = listed_sha256(Path::new("models/piper/en_US-joe-medium.durations.onnx"));
        assert!(relative.is_some_and(|sum| sum.len() == 64));
        let absolute = listed_sha256(Path::new(
            "/somewhere/checkout/models/piper/en_US-joe-medium.durations.onnx",
        ));
        assert_eq!(relative, absolute);
        // A name that merely ends the same way is another file.
        assert_eq!(
            listed_sha256(Path::new(
                "/x/othermodels/piper/en_US-joe-medium.durations.onnx"
            )),
            None
        );
        assert_eq!(listed_sha256(Path::new("models/piper/unknown.onnx")), None);
    }

    #[test]
    fn a_missing_or_different_file_names_path_checksum_and_target() {
        let dir = std::env::temp_dir().join(format!("voice-checksum-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let missing = dir.join("missing.onnx");
        let message = verify(&missing, Some("ab12"), "Piper voice")
            .expect_err("missing")
            .to_string();
        assert!(
            message.contains(&missing.display().to_string())
                && message.contains("ab12")
                && message.contains(MAKE_TARGET)
                && message.contains("missing"),
            "{message}"
        );
        let other = dir.join("other.onnx");
        std::fs::write(&other, b"not a voice").expect("write");
        let message = verify(&other, Some("ab12"), "Piper voice")
            .expect_err("different")
            .to_string();
        assert!(
            message.contains(&file_sha256(&other).expect("hash")) && message.contains("ab12"),
            "{message}"
        );
        let right = file_sha256(&other).expect("hash");
        assert!(verify(&other, Some(&right), "Piper voice").is_ok());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
