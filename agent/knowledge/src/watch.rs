//! Telling the owner that the knowledge folder changed: inotify (the `notify` crate) on the folder, debounced on a
//! thread that sleeps in a blocking receive between changes, so an unchanged folder costs nothing. A folder that
//! does not exist yet is waited for by watching its nearest existing parent.

use std::path::{Component, Path, PathBuf};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use notify::{Config, Event, EventKindMask, RecommendedWatcher, RecursiveMode, Watcher};

use crate::error::KnowledgeError;
use crate::folder;

/// How long the folder must stay quiet before the owner is told: an editor's save (a temporary file written,
/// renamed, its attributes set) or a copied folder arrives as a burst of events, and re-indexing once per burst
/// is enough.
pub const DEBOUNCE: Duration = Duration::from_millis(300);

/// The longest a burst may hold the notice back: a file written for seconds on end is still reported.
const MAX_DELAY: Duration = Duration::from_secs(2);

/// Watching a folder; dropping it stops the watch and waits for its thread (a notice in progress finishes first).
#[derive(Debug)]
pub struct FolderWatch {
    stop: Sender<Message>,
    thread: Option<JoinHandle<()>>,
}

impl Drop for FolderWatch {
    fn drop(&mut self) {
        let _ = self.stop.send(Message::Stop);
        if let Some(thread) = self.thread.take() {
            // A callback that drops its own watch must not wait for itself.
            if thread.thread().id() != std::thread::current().id() {
                let _ = thread.join();
            }
        }
    }
}

enum Message {
    Fs(notify::Result<Event>),
    Stop,
}

/// What the watcher is registered on.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Armed {
    /// The folder itself, recursively.
    Folder,
    /// The nearest existing parent of a folder that does not exist yet, that one level only.
    Parent(PathBuf),
}

/// Calls `on_change` (on the watch's own thread) each time the folder's Markdown or text files, or its
/// subfolders, change, once per burst of changes after [`DEBOUNCE`] of quiet; also when a folder that did not
/// exist appears or the folder is removed. Hidden files and other extensions are ignored. Keep `on_change` short:
/// send a message or start the re-index elsewhere. A path that exists and is not a directory is an error.
pub fn watch(
    dir: impl AsRef<Path>,
    on_change: impl Fn() + Send + 'static,
) -> Result<FolderWatch, KnowledgeError> {
    let given = dir.as_ref();
    let watch_error = |source| KnowledgeError::Watch {
        path: given.to_path_buf(),
        source,
    };
    // Events name absolute paths once the watch is on an absolute one, whatever the working directory.
    let dir = std::path::absolute(given).map_err(|e| watch_error(notify::Error::io(e)))?;
    if dir.exists() && !dir.is_dir() {
        return Err(KnowledgeError::NotADirectory {
            path: given.to_path_buf(),
        });
    }
    let (tx, rx) = mpsc::channel();
    let events = tx.clone();
    let mut watcher = RecommendedWatcher::new(
        move |event| {
            let _ = events.send(Message::Fs(event));
        },
        // Without access events: reading the files to index them must not look like a change.
        Config::default().with_event_kinds(EventKindMask::CORE),
    )
    .map_err(watch_error)?;
    let armed = arm(&mut watcher, &dir).map_err(watch_error)?;
    let thread = std::thread::Builder::new()
        .name("knowledge-watch".into())
        .spawn(move || run(watcher, armed, &dir, &rx, on_change))
        .map_err(|e| watch_error(notify::Error::io(e)))?;
    Ok(FolderWatch {
        stop: tx,
        thread: Some(thread),
    })
}

fn arm(watcher: &mut RecommendedWatcher, dir: &Path) -> notify::Result<Armed> {
    if dir.is_dir() {
        watcher.watch(dir, RecursiveMode::Recursive)?;
        return Ok(Armed::Folder);
    }
    let mut parent = dir.parent();
    while let Some(p) = parent {
        if p.is_dir() {
            watcher.watch(p, RecursiveMode::NonRecursive)?;
            return Ok(Armed::Parent(p.to_path_buf()));
        }
        parent = p.parent();
    }
    Err(notify::Error::path_not_found().add_path(dir.to_path_buf()))
}

fn unarm(watcher: &mut RecommendedWatcher, dir: &Path, armed: &Armed) {
    // The watch may be gone already (the folder was removed); there is nothing to undo then.
    let _ = match armed {
        Armed::Folder => watcher.unwatch(dir),
        Armed::Parent(p) => watcher.unwatch(p),
    };
}

fn run(
    mut watcher: RecommendedWatcher,
    mut armed: Armed,
    dir: &Path,
    rx: &Receiver<Message>,
    on_change: impl Fn(),
) {
    loop {
        // Asleep until something happens: no timer runs while the folder is unchanged.
        match rx.recv() {
            Ok(Message::Fs(event)) if relevant(&event, dir, &armed) => {}
            Ok(Message::Fs(_)) => continue,
            Ok(Message::Stop) | Err(_) => return,
        }
        let first = Instant::now();
        let mut last = first;
        loop {
            let deadline = (last + DEBOUNCE).min(first + MAX_DELAY);
            match rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
                Ok(Message::Fs(event)) => {
                    if relevant(&event, dir, &armed) {
                        last = Instant::now();
                    }
                }
                Ok(Message::Stop) | Err(RecvTimeoutError::Disconnected) => return,
                Err(RecvTimeoutError::Timeout) => break,
            }
        }
        // The folder appeared (watch it now) or went away (wait for it at its parent again).
        let wanted_folder = dir.is_dir();
        if wanted_folder != (armed == Armed::Folder) {
            unarm(&mut watcher, dir, &armed);
            match arm(&mut watcher, dir) {
                Ok(now) => armed = now,
                // Nothing left to watch (every parent gone): tell the owner, who will find the folder empty.
                Err(_) => {
                    on_change();
                    return;
                }
            }
        }
        on_change();
    }
}

/// Whether an event can change what the folder holds: an error (events lost: assume so), or a path under the
/// folder that is not hidden and is a Markdown or text file or may be a folder; while waiting at a parent, only
/// the path on the way to the folder.
fn relevant(event: &notify::Result<Event>, dir: &Path, armed: &Armed) -> bool {
    let Ok(event) = event else {
        return true;
    };
    event.paths.iter().any(|path| match armed {
        Armed::Parent(_) => dir.starts_with(path),
        Armed::Folder => relevant_path(path, dir),
    })
}

fn relevant_path(path: &Path, dir: &Path) -> bool {
    let Ok(relative) = path.strip_prefix(dir) else {
        return false;
    };
    let names: Vec<_> = relative
        .components()
        .filter_map(|c| match c {
            Component::Normal(n) => Some(n.to_string_lossy()),
            _ => None,
        })
        .collect();
    let Some(last) = names.last() else {
        // The folder itself (removed, renamed).
        return true;
    };
    if names.iter().any(|n| n.starts_with('.')) {
        return false;
    }
    // A name without an extension may be a folder (one removed no longer says so).
    folder::format_of(last).is_some() || !last.contains('.') || path.is_dir()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Long enough for a loaded machine; the tests end as soon as the notice comes.
    const DEADLINE: Duration = Duration::from_secs(20);

    fn notices() -> (impl Fn() + Send + 'static, Receiver<()>) {
        let (tx, rx) = mpsc::channel();
        (
            move || {
                let _ = tx.send(());
            },
            rx,
        )
    }

    #[test]
    fn a_file_added_to_a_watched_folder_calls_back() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (on_change, rx) = notices();
        let _watch = watch(dir.path(), on_change).expect("watch");
        std::fs::create_dir(dir.path().join("sub")).expect("mkdir");
        std::fs::write(dir.path().join("sub/new.md"), "# New").expect("write");
        rx.recv_timeout(DEADLINE).expect("a notice");
    }

    #[test]
    fn a_folder_created_after_the_watch_began_calls_back() {
        let parent = tempfile::tempdir().expect("tempdir");
        let dir = parent.path().join("knowledge");
        let (on_change, rx) = notices();
        let _watch = watch(&dir, on_change).expect("watch");
        std::fs::create_dir(&dir).expect("mkdir");
        rx.recv_timeout(DEADLINE).expect("a notice for the folder");
        // Now the folder itself is watched.
        std::fs::write(dir.join("a.txt"), "hello").expect("write");
        rx.recv_timeout(DEADLINE).expect("a notice for the file");
    }

    #[test]
    fn hidden_files_and_other_extensions_are_not_changes() {
        let dir = Path::new("/k");
        assert!(!relevant_path(Path::new("/k/.a.md.swp"), dir));
        assert!(!relevant_path(Path::new("/k/.git/config"), dir));
        assert!(!relevant_path(Path::new("/k/a.md~"), dir));
        assert!(!relevant_path(Path::new("/other/a.md"), dir));
        assert!(relevant_path(Path::new("/k/a.md"), dir));
        assert!(relevant_path(Path::new("/k/sub/b.txt"), dir));
        assert!(relevant_path(Path::new("/k/removed-folder"), dir));
        assert!(relevant_path(Path::new("/k"), dir));
    }

    #[test]
    fn watching_a_path_that_is_a_file_is_an_error_naming_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join("notes.txt");
        std::fs::write(&file, "x").expect("write");
        let err = watch(&file, || {}).expect_err("a file");
        assert!(err.to_string().contains("notes.txt"), "{err}");
    }

    #[test]
    fn dropping_the_watch_ends_its_thread() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (on_change, _rx) = notices();
        let watch = watch(dir.path(), on_change).expect("watch");
        // Drop joins the thread: this returns only once it has ended.
        drop(watch);
    }
}
