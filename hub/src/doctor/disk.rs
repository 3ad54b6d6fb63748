//! The doctor's data-directory check: the folder writable (tokens, the pair database, the socket, the certificate)
//! and enough free space for recordings and the pair database.

use std::path::{Path, PathBuf};

use super::finding::Finding;

/// Below this much free space the doctor warns: a recording fills megabytes a minute and a full disk makes the
/// pair database refuse writes.
pub const LOW_SPACE: u64 = 500 * 1_000_000;
/// Below this much the disk is as good as full: the pair database's next writes (a page of its file at a time) and
/// the tokens at start may not fit.
pub const FULL: u64 = 16 * 1_000_000;

/// The facts the data-directory findings are made from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Facts {
    pub path: PathBuf,
    /// Whether the folder exists (the agent makes it at first start if it can).
    pub exists: bool,
    /// Writing a file there (or, when it does not exist, in the nearest folder above it that does).
    pub writable: Result<(), String>,
    /// Free bytes for an unprivileged user on its file system, if known.
    pub free: Option<u64>,
}

/// Gathers the facts about `dir`.
pub fn gather(dir: &Path) -> Facts {
    let exists = dir.is_dir();
    let probe_dir = dir
        .ancestors()
        .find(|p| p.is_dir())
        .unwrap_or(Path::new("."))
        .to_path_buf();
    let probe_file = probe_dir.join(format!(".doctor-{}", std::process::id()));
    let writable = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe_file)
        .map(|_| {
            let _ = std::fs::remove_file(&probe_file);
        })
        .map_err(|e| format!("{}: {e}", probe_dir.display()));
    let free = rustix::fs::statvfs(&probe_dir)
        .ok()
        .map(|s| s.f_bavail.saturating_mul(s.f_frsize));
    Facts {
        path: dir.to_path_buf(),
        exists,
        writable,
        free,
    }
}

/// The findings for the data directory.
pub fn findings(facts: &Facts) -> Vec<Finding> {
    let shown = facts.path.display();
    let mut out = Vec::new();
    match (&facts.writable, facts.exists) {
        (Ok(()), true) => out.push(Finding::ok("data", format!("{shown} is writable"))),
        (Ok(()), false) => out.push(Finding::ok(
            "data",
            format!("{shown} does not exist yet; the agent makes it at first start"),
        )),
        (Err(why), _) => out.push(Finding::problem(
            "data",
            format!("{shown} is not writable ({why}): the agent cannot keep its tokens, pair database and socket"),
            "give the agent's user the folder (chown), or choose another with --data-dir or [server] data_dir",
        )),
    }
    match facts.free {
        Some(free) if free < FULL => out.push(Finding::problem(
            "data",
            format!(
                "{shown}'s file system is full ({} kB free): the pair database refuses writes and recordings stop",
                free / 1000
            ),
            "free space on that file system (old recordings in the data directory's recordings), or move the data \
             directory with --data-dir",
        )),
        Some(free) if free < LOW_SPACE => out.push(Finding::warning(
            "data",
            format!(
                "{shown} has {} MB free, under {} MB: recordings need room and a full disk makes the pair \
                 database refuse writes",
                free / 1_000_000,
                LOW_SPACE / 1_000_000
            ),
            "free space on that file system, or move the data directory with --data-dir",
        )),
        Some(free) => out.push(Finding::ok(
            "data",
            format!("{shown} has {} MB free", free / 1_000_000),
        )),
        None => {}
    }
    out
}

/// Gathers the facts about `dir` and makes its findings.
pub fn check(dir: &Path) -> Vec<Finding> {
    findings(&gather(dir))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::Level;

    fn facts(writable: Result<(), String>, free: Option<u64>) -> Facts {
        Facts {
            path: "/var/lib/robot-agent".into(),
            exists: true,
            writable,
            free,
        }
    }

    #[test]
    fn a_writable_folder_with_room_is_fine() {
        let f = findings(&facts(Ok(()), Some(10 * LOW_SPACE)));
        assert!(f.iter().all(|f| f.level == Level::Ok), "{f:?}");
    }

    #[test]
    fn a_full_disk_is_a_problem_with_the_fix() {
        let f = findings(&facts(Ok(()), Some(200_000)));
        let full = f.iter().find(|x| x.text.contains("full")).expect("named");
        assert_eq!(full.level, Level::Problem);
        assert!(
            full.fix
                .as_deref()
                .is_some_and(|fix| fix.contains("free space"))
        );
    }

    #[test]
    fn little_free_space_is_a_warning_that_says_why() {
        let f = findings(&facts(Ok(()), Some(LOW_SPACE / 2)));
        let low = f
            .iter()
            .find(|f| f.level == Level::Warning)
            .expect("a warning");
        assert!(low.text.contains("250 MB free"), "{low}");
        assert!(
            low.text.contains("recordings") && low.text.contains("pair database"),
            "{low}"
        );
    }

    #[test]
    fn a_folder_that_cannot_be_written_is_a_problem() {
        let f = findings(&facts(Err("permission denied".into()), None));
        assert_eq!(f.len(), 1);
        assert_eq!(f[0].level, Level::Problem);
        assert!(
            f[0].fix.as_deref().unwrap_or("").contains("--data-dir"),
            "{}",
            f[0]
        );
    }

    #[test]
    fn a_temporary_folder_is_found_writable_and_its_space_known() {
        let dir = tempfile::tempdir().expect("temp dir");
        let facts = gather(&dir.path().join("not-yet"));
        assert!(!facts.exists);
        assert_eq!(facts.writable, Ok(()));
        assert!(facts.free.is_some());
    }
}
