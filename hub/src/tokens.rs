//! Authentication tokens: generated at first start into the data directory
//! (mode 0600), read by flowctl and satellites, compared in constant time.
//!
//! Three credentials, each granting less than the next: the page token opens
//! the avatar page and the HTTP API (it is what the printed URL carries); the
//! user token logs a satellite in to the hub; the admin token also lets it
//! remove anyone's channel. See docs/security.md.

use std::io::Write;
use std::path::Path;

use rand::Rng;

/// File holding the token every satellite uses.
pub const TOKEN_FILE: &str = "token";
/// File holding the token that grants admin rights (remove anyone's channel).
pub const ADMIN_TOKEN_FILE: &str = "admin.token";
/// File holding the page token: the credential in the page's URL.
pub const PAGE_TOKEN_FILE: &str = "page.token";

/// A token file that could not be read or written.
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct TokenError {
    pub path: std::path::PathBuf,
    #[source]
    pub source: std::io::Error,
}

/// The tokens a login or a page may present.
#[derive(Clone)]
pub struct Tokens {
    user: String,
    admin: String,
    page: String,
}

impl std::fmt::Debug for Tokens {
    /// Tokens never appear in logs, not even through `Debug`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Tokens(<redacted>)")
    }
}

impl Tokens {
    /// Loads the tokens from `dir`, creating any that is missing.
    pub fn load_or_create(dir: &Path) -> Result<Tokens, TokenError> {
        let file = |name: &str| {
            let path = dir.join(name);
            load_or_create(&path).map_err(|source| TokenError { path, source })
        };
        Ok(Tokens {
            user: file(TOKEN_FILE)?,
            admin: file(ADMIN_TOKEN_FILE)?,
            page: file(PAGE_TOKEN_FILE)?,
        })
    }

    /// `Some(is_admin)` if the token is valid.
    pub fn check(&self, presented: &str) -> Option<bool> {
        if constant_time_eq(presented.as_bytes(), self.admin.as_bytes()) {
            Some(true)
        } else if constant_time_eq(presented.as_bytes(), self.user.as_bytes()) {
            Some(false)
        } else {
            None
        }
    }

    /// Whether `presented` is the page token.
    pub fn is_page(&self, presented: &str) -> bool {
        constant_time_eq(presented.as_bytes(), self.page.as_bytes())
    }

    /// The page token: it goes into the URL the server prints, and keys the page's session cookies.
    pub fn page(&self) -> &str {
        &self.page
    }

    /// The admin token, for modules started inside the server.
    pub fn admin(&self) -> &str {
        &self.admin
    }
}

fn load_or_create(path: &Path) -> std::io::Result<String> {
    match std::fs::read_to_string(path) {
        Ok(text) if !text.trim().is_empty() => return Ok(text.trim().to_string()),
        Ok(_) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(e),
    }
    let token: String = rand::rng()
        .sample_iter(rand::distr::Alphanumeric)
        .take(40)
        .map(char::from)
        .collect();
    let mut opts = std::fs::OpenOptions::new();
    opts.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.mode(0o600);
    }
    let mut file = opts.open(path)?;
    writeln!(file, "{token}")?;
    file.sync_all()?;
    Ok(token)
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}
