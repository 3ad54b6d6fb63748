//! Finding espeak-ng's compiled data (`phontab`, `*_dict`, `lang/`, `voices/`).
//!
//! `espeak-rs-sys` builds the espeak-ng library from source but does not compile its data, and the path baked
//! into that build points inside cargo's target directory, where nothing exists. The data therefore comes from
//! the system: Debian's `espeak-ng-data` package (a dependency of the `espeak-ng` package) installs it in
//! `/usr/lib/<multiarch>/espeak-ng-data`. Its format version (1.51) is the one the bundled 1.52 library reads.

use std::path::{Path, PathBuf};

use crate::error::VoiceError;

/// espeak-ng's own environment variable for the data location, honoured here too.
pub const DATA_PATH_ENV: &str = "ESPEAK_DATA_PATH";

/// Returns the espeak-ng data directory: `explicit` if given, else `$ESPEAK_DATA_PATH`, else the first of the
/// usual system locations that holds a `phontab`. A candidate may be the data directory itself or a directory
/// containing `espeak-ng-data/` (espeak-ng accepts both forms).
pub fn locate_data(explicit: Option<&Path>) -> Result<PathBuf, VoiceError> {
    let mut candidates: Vec<PathBuf> = Vec::new();
    match explicit {
        // An explicit path is the only candidate: silently falling back to another location would hide a
        // configuration mistake.
        Some(path) => candidates.push(path.to_path_buf()),
        None => {
            if let Some(path) = std::env::var_os(DATA_PATH_ENV).filter(|p| !p.is_empty()) {
                candidates.push(PathBuf::from(path));
            }
            candidates.push(PathBuf::from(format!(
                "/usr/lib/{}-linux-gnu/espeak-ng-data",
                std::env::consts::ARCH
            )));
            candidates.push(PathBuf::from("/usr/share/espeak-ng-data"));
            candidates.push(PathBuf::from("/usr/local/share/espeak-ng-data"));
            candidates.push(PathBuf::from("/usr/lib/espeak-ng-data"));
        }
    }
    for candidate in &candidates {
        if candidate.join("phontab").is_file() {
            return Ok(candidate.clone());
        }
        let nested = candidate.join("espeak-ng-data");
        if nested.join("phontab").is_file() {
            return Ok(nested);
        }
    }
    Err(VoiceError::DataNotFound {
        searched: candidates,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn explicit_path_without_data_is_an_error_naming_it() {
        let missing = Path::new("/nonexistent/espeak-data-for-test");
        let error =
            locate_data(Some(missing)).expect_err("a missing directory must not be accepted");
        match error {
            VoiceError::DataNotFound { searched } => {
                assert_eq!(searched, vec![missing.to_path_buf()])
            }
            other => panic!("unexpected error {other}"),
        }
    }

    #[test]
    fn system_data_is_found() {
        let found = locate_data(None)
            .expect("espeak-ng-data must be installed (Debian package espeak-ng-data)");
        assert!(found.join("phontab").is_file());
        assert!(found.join("en_dict").is_file() && found.join("it_dict").is_file());
    }
}
