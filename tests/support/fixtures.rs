//! Locating the shared fixtures (real recordings and images).

use std::path::PathBuf;

/// `$AGENT_FIXTURES`, else `shared/fixtures` beside the repository.
pub fn fixtures() -> PathBuf {
    if let Some(dir) = std::env::var_os("AGENT_FIXTURES") {
        return PathBuf::from(dir);
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/fixtures")
        .canonicalize()
        .unwrap_or_else(|_| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/fixtures"))
}

/// A fixture file by its path inside the fixtures directory; fails clearly if missing.
pub fn fixture(relative: &str) -> anyhow::Result<PathBuf> {
    let path = fixtures().join(relative);
    anyhow::ensure!(
        path.is_file(),
        "fixture {} is missing (set AGENT_FIXTURES to the shared fixtures directory)",
        path.display()
    );
    Ok(path)
}
