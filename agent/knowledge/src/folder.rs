//! The files of a knowledge folder: Markdown and text files found recursively, read whole; hidden files, other
//! extensions and files over [`MAX_FILE_BYTES`] are left out, the last two kinds counted as skipped.

use std::path::Path;

use crate::error::KnowledgeError;

/// The largest file indexed. The folder is meant for a few pages of facts to speak aloud; a bigger file is almost
/// certainly something copied in by mistake (a log, a dump) that would drown the real passages.
pub const MAX_FILE_BYTES: u64 = 1 << 20;

/// How a file's text is split into passages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// `.md`: headings, lists and inline markup.
    Markdown,
    /// `.txt`: paragraphs only.
    Text,
}

/// One file to index.
#[derive(Debug, Clone)]
pub struct SourceFile {
    /// Relative to the folder, `/`-separated.
    pub relative: String,
    pub format: Format,
    pub text: String,
}

/// A file that was found but not indexed, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped {
    /// Relative to the folder, `/`-separated.
    pub path: String,
    pub reason: SkipReason,
}

/// Why a file was not indexed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SkipReason {
    /// Over [`MAX_FILE_BYTES`].
    TooLarge { bytes: u64 },
    /// It could not be read (permissions, removed while listing); the message says why.
    Unreadable(String),
}

/// What a folder holds.
#[derive(Debug, Default)]
pub struct Listing {
    /// In path order, so that the same folder always gives the same index.
    pub files: Vec<SourceFile>,
    pub skipped: Vec<Skipped>,
}

/// Reads every Markdown and text file under `dir`. A folder that does not exist (yet) is empty, not an error: the
/// watcher reports it when it appears. A path that exists and is not a directory is an error.
pub fn read(dir: &Path) -> Result<Listing, KnowledgeError> {
    match std::fs::metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Listing::default()),
        Err(source) => {
            return Err(KnowledgeError::Folder {
                path: dir.to_path_buf(),
                source,
            });
        }
        Ok(meta) if !meta.is_dir() => {
            return Err(KnowledgeError::NotADirectory {
                path: dir.to_path_buf(),
            });
        }
        Ok(_) => {}
    }
    let entries = std::fs::read_dir(dir).map_err(|source| KnowledgeError::Folder {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut listing = Listing::default();
    walk(entries, "", &mut listing);
    listing.files.sort_by(|a, b| a.relative.cmp(&b.relative));
    Ok(listing)
}

/// The format a file name asks for, or `None` for a file that is not indexed (hidden, other extension).
pub fn format_of(name: &str) -> Option<Format> {
    if name.starts_with('.') {
        return None;
    }
    let (_, ext) = name.rsplit_once('.')?;
    match ext.to_ascii_lowercase().as_str() {
        "md" | "markdown" => Some(Format::Markdown),
        "txt" => Some(Format::Text),
        _ => None,
    }
}

fn walk(entries: std::fs::ReadDir, prefix: &str, listing: &mut Listing) {
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') {
            continue;
        }
        let relative = format!("{prefix}{name}");
        let path = entry.path();
        // A symbolic link to a directory is not followed, so that a link back up cannot make the walk endless;
        // a link to a file is read like the file.
        let is_dir = entry.file_type().map(|t| t.is_dir()).unwrap_or(false);
        if is_dir {
            match std::fs::read_dir(&path) {
                Ok(inner) => walk(inner, &format!("{relative}/"), listing),
                Err(e) => listing.skipped.push(Skipped {
                    path: relative,
                    reason: SkipReason::Unreadable(e.to_string()),
                }),
            }
            continue;
        }
        let Some(format) = format_of(&name) else {
            continue;
        };
        match read_file(&path) {
            Ok(text) => listing.files.push(SourceFile {
                relative,
                format,
                text,
            }),
            Err(reason) => listing.skipped.push(Skipped {
                path: relative,
                reason,
            }),
        }
    }
}

fn read_file(path: &Path) -> Result<String, SkipReason> {
    let meta = std::fs::metadata(path).map_err(|e| SkipReason::Unreadable(e.to_string()))?;
    if !meta.is_file() {
        return Err(SkipReason::Unreadable("not a regular file".into()));
    }
    if meta.len() > MAX_FILE_BYTES {
        return Err(SkipReason::TooLarge { bytes: meta.len() });
    }
    let bytes = std::fs::read(path).map_err(|e| SkipReason::Unreadable(e.to_string()))?;
    // A file in another encoding still gives its ASCII words rather than nothing.
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markdown_and_text_files_are_found_in_subfolders_and_others_are_left_out() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::create_dir(dir.path().join("sub")).expect("mkdir");
        std::fs::write(dir.path().join("a.md"), "# A").expect("write");
        std::fs::write(dir.path().join("sub/b.txt"), "B").expect("write");
        std::fs::write(dir.path().join("c.rs"), "fn main() {}").expect("write");
        std::fs::write(dir.path().join(".hidden.md"), "no").expect("write");
        let listing = read(dir.path()).expect("read");
        let names: Vec<&str> = listing.files.iter().map(|f| f.relative.as_str()).collect();
        assert_eq!(names, ["a.md", "sub/b.txt"]);
        assert!(listing.skipped.is_empty());
    }

    #[test]
    fn a_file_over_the_limit_is_skipped_and_counted() {
        let dir = tempfile::tempdir().expect("tempdir");
        let big = "x".repeat(MAX_FILE_BYTES as usize + 1);
        std::fs::write(dir.path().join("big.txt"), big).expect("write");
        let listing = read(dir.path()).expect("read");
        assert!(listing.files.is_empty());
        assert_eq!(listing.skipped.len(), 1);
        assert!(matches!(
            listing.skipped[0].reason,
            SkipReason::TooLarge { .. }
        ));
    }

    #[test]
    fn a_folder_that_does_not_exist_is_empty() {
        let dir = tempfile::tempdir().expect("tempdir");
        let listing = read(&dir.path().join("not-yet")).expect("read");
        assert!(listing.files.is_empty());
    }

    #[test]
    fn a_path_that_is_a_file_is_an_error_naming_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join("notes.md");
        std::fs::write(&file, "# Notes").expect("write");
        let err = read(&file).expect_err("a file is not a folder");
        let message = err.to_string();
        assert!(message.contains("notes.md"), "{message}");
        assert!(message.contains("not a directory"), "{message}");
    }
}
