//! Where the models live: the default `models/ggml-tiny.en.bin` in the repository (or `WHISPER_MODEL`), and the
//! files that model names such as `base` stand for.

use std::path::{Path, PathBuf};

/// File name `make model` produces.
pub const DEFAULT_MODEL_FILE: &str = "models/ggml-tiny.en.bin";

/// The repository root, found from this crate's manifest directory (satellites/whisper-sat).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// The model to load when none is given: `WHISPER_MODEL` if set, else the converted tiny.en in the repository.
pub fn default_model() -> PathBuf {
    match std::env::var_os("WHISPER_MODEL") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => repo_root().join(DEFAULT_MODEL_FILE),
    }
}

/// What `--model` names: an existing file as it is; a bare name such as `base` or `tiny.en` (no directory, no
/// `.bin`) the file `make model MODEL=<name>` provisions, `models/ggml-<name>.bin` in the repository.
pub fn resolve_model(arg: &Path) -> PathBuf {
    let bare = arg.components().count() == 1
        && arg.extension().is_none_or(|e| e != "bin")
        && !arg.is_file();
    if bare {
        repo_root().join(format!("models/ggml-{}.bin", arg.display()))
    } else {
        arg.to_path_buf()
    }
}

/// The speech clips in the fixture directory's `audio/` (`NAME.wav` with its reference `NAME.txt`), which the
/// model tests and the benchmark run on.
pub const FIXTURE_CLIPS: [&str; 5] = [
    "jfk",
    "LJ001-0001",
    "LJ001-0002",
    "LJ001-0004",
    "sb_example1",
];

/// The shared fixture directory: `AGENT_FIXTURES`, else `shared/fixtures` beside the repository.
pub fn fixtures_dir() -> PathBuf {
    match std::env::var_os("AGENT_FIXTURES") {
        // A relative setting is read against the repository root, like the default.
        Some(p) if !p.is_empty() => repo_root().join(p),
        _ => repo_root().join("../shared/fixtures"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bare_model_name_stands_for_the_file_make_model_provisions() {
        assert_eq!(
            resolve_model(Path::new("base")),
            repo_root().join("models/ggml-base.bin")
        );
        assert_eq!(
            resolve_model(Path::new("tiny.en")),
            repo_root().join("models/ggml-tiny.en.bin")
        );
        // Paths and file names are taken as they are.
        assert_eq!(
            resolve_model(Path::new("/opt/m/ggml-small.bin")),
            PathBuf::from("/opt/m/ggml-small.bin")
        );
        assert_eq!(
            resolve_model(Path::new("ggml-small.bin")),
            PathBuf::from("ggml-small.bin")
        );
    }
}
