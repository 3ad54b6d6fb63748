//! The login tokens a robot-agent writes into its data directory, read the way every satellite on the same
//! machine reads them (`--token`, else the file in `--data-dir`).

use std::path::{Path, PathBuf};

/// Which of the server's two tokens.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TokenKind {
    /// `DATA_DIR/token`: publish, subscribe, serve, use the pair database.
    User,
    /// `DATA_DIR/admin.token`: also remove other peers' channels.
    Admin,
}

impl TokenKind {
    pub fn file_name(self) -> &'static str {
        match self {
            TokenKind::User => "token",
            TokenKind::Admin => "admin.token",
        }
    }
}

/// The token file could not be read.
#[derive(Debug, thiserror::Error)]
#[error("no token: pass --token or point --data-dir at the server's data ({})", path.display())]
pub struct TokenError {
    pub path: PathBuf,
    #[source]
    pub source: std::io::Error,
}

/// `explicit` when given, else the token of `kind` from the server's data directory, without surrounding
/// whitespace (the server ends the file with a newline).
pub fn resolve_token(
    explicit: Option<&str>,
    data_dir: &Path,
    kind: TokenKind,
) -> Result<String, TokenError> {
    if let Some(token) = explicit {
        return Ok(token.to_owned());
    }
    let path = data_dir.join(kind.file_name());
    match std::fs::read_to_string(&path) {
        Ok(text) => Ok(text.trim().to_owned()),
        Err(source) => Err(TokenError { path, source }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn explicit_wins_then_the_file_is_read_and_trimmed() {
        let dir = std::env::temp_dir().join(format!("flow-token-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        std::fs::write(dir.join("token"), "abc123\n").expect("write");
        assert_eq!(
            resolve_token(Some("given"), &dir, TokenKind::User).expect("explicit"),
            "given"
        );
        assert_eq!(
            resolve_token(None, &dir, TokenKind::User).expect("file"),
            "abc123"
        );
        let missing = resolve_token(None, &dir, TokenKind::Admin).expect_err("no admin token file");
        assert!(missing.to_string().contains("admin.token"), "{missing}");
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}
