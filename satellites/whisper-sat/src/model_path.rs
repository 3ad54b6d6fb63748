//! Where the default model lives: `models/ggml-tiny.en.bin` in the repository, or `WHISPER_MODEL`.

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
