//! Why a knowledge folder could not be indexed or watched: each error names the path and the reason.

use std::path::PathBuf;

/// A failure of [`crate::Knowledge::open`] or [`crate::watch`].
#[derive(Debug, thiserror::Error)]
pub enum KnowledgeError {
    /// The path exists but is a file (or something else), so it cannot be a knowledge folder.
    #[error("{}: not a directory", path.display())]
    NotADirectory { path: PathBuf },
    /// The folder itself (not one file in it) could not be listed.
    #[error("{}: cannot read the folder: {source}", path.display())]
    Folder {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The search engine refused to build or query the index (in RAM, so this is not expected to happen).
    #[error("{}: cannot index the folder: {source}", path.display())]
    Index {
        path: PathBuf,
        #[source]
        source: tantivy::TantivyError,
    },
    /// The operating system would not watch the folder (for example inotify's watch limit is reached).
    #[error("{}: cannot watch the folder: {source}", path.display())]
    Watch {
        path: PathBuf,
        #[source]
        source: notify::Error,
    },
}
