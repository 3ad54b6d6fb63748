//! Machine-local sharing of CPU cores between the whisper satellites of one machine, through file locks.
//!
//! whisper.cpp (1.8.3, built without OpenMP) waits at the barrier between two operations by spinning, never
//! yielding, so two satellites whose inference threads together outnumber the cores starve each other: a thread
//! spins out its whole time slice waiting for a peer that the scheduler has parked (on two cores, two satellites
//! with two threads each ran 35 times slower than one). The operator scales ASR by starting more satellites, so
//! the satellites themselves keep the total of inference threads at or below the cores:
//!
//! - Every satellite is a **member**: it holds an exclusive lock on its own `member-<pid>-<n>` file in the shared
//!   directory for as long as it runs. Counting members means trying each member file's lock; one that can be
//!   taken belongs to a satellite that has gone (the kernel drops a dead process's locks) and is removed.
//! - A decode takes a **lease** of up to its **fair share** of cores, `cores / members` (at least one, at most its
//!   `--threads`): it locks that many of the `slot-<k>` files, one per core, and runs with one thread per slot
//!   held. With every slot taken it waits, checking every [`WAIT_STEP`] (only while all cores are busy decoding)
//!   and giving up when its abort flag is set; a free slot is never left unused while it waits.
//!
//! Fair shares rather than "take every free core" keep a short utterance from waiting behind a long one on
//! another satellite: each member's share is free for it whenever it needs it. The price is that a lone decode
//! with N members on the machine runs on 1/N of the cores (docs/asr.md, "Several satellites on one machine").
//! Locks die with their process, so a killed satellite never leaves a core taken.

use std::fs::{File, OpenOptions, TryLockError};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use crate::abort::AbortFlag;

/// How often a decode that found every core taken looks again.
pub const WAIT_STEP: Duration = Duration::from_millis(2);

/// Errors from joining the shared directory.
#[derive(Debug, thiserror::Error)]
pub enum CoreShareError {
    #[error("core share directory {path}: {source}")]
    Directory {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("core share member file {path}: {source}")]
    Member {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("a core share needs at least one core")]
    NoCores,
}

/// The default shared directory: per user, so satellites of different users never share (or fight over) files.
pub fn default_dir() -> PathBuf {
    if let Some(runtime) = std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        return PathBuf::from(runtime).join("whisper-sat-cores");
    }
    let user = std::env::var("USER").unwrap_or_else(|_| "default".into());
    std::env::temp_dir().join(format!("whisper-sat-cores-{user}"))
}

/// The cores this machine offers to inference (what the process may run on).
pub fn machine_cores() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
}

/// Numbers member files apart when one process joins more than once (the bench's in-process workers).
static NEXT_MEMBER: AtomicU64 = AtomicU64::new(0);

/// One satellite's membership in the machine's core share.
#[derive(Debug)]
pub struct CoreShare {
    dir: PathBuf,
    cores: usize,
    member_path: PathBuf,
    /// Held locked for the member's lifetime; closing it (on drop or death) is what leaving means.
    _member: File,
    /// Where this member starts looking for a free slot, so members do not all contend for slot 0.
    first_slot: usize,
}

/// Cores held for one decode; dropping it gives them back.
#[derive(Debug)]
pub struct CoreLease {
    slots: Vec<File>,
}

impl CoreLease {
    /// Inference threads this lease allows: one per core held.
    pub fn threads(&self) -> usize {
        self.slots.len()
    }
}

impl CoreShare {
    /// Joins the share of `cores` cores kept in `dir`, creating the directory if needed.
    pub fn join(dir: &Path, cores: usize) -> Result<Self, CoreShareError> {
        if cores == 0 {
            return Err(CoreShareError::NoCores);
        }
        std::fs::create_dir_all(dir).map_err(|source| CoreShareError::Directory {
            path: dir.to_path_buf(),
            source,
        })?;
        let n = NEXT_MEMBER.fetch_add(1, Ordering::Relaxed);
        let member_path = dir.join(format!("member-{}-{n}", std::process::id()));
        // The file is locked under another name and then renamed, so no member counting at that moment can take
        // an unlocked member file for a stale one and remove it from under its owner.
        let joining = dir.join(format!("joining-{}-{n}", std::process::id()));
        let member_error = |source| CoreShareError::Member {
            path: member_path.clone(),
            source,
        };
        let member = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&joining)
            .map_err(member_error)?;
        member.try_lock().map_err(|e| match e {
            TryLockError::WouldBlock => member_error(std::io::Error::other(
                "already locked by another process with this process id",
            )),
            TryLockError::Error(e) => member_error(e),
        })?;
        std::fs::rename(&joining, &member_path).map_err(member_error)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            cores,
            first_slot: (std::process::id() as usize).wrapping_add(n as usize) % cores,
            member_path,
            _member: member,
        })
    }

    /// The cores shared.
    pub fn cores(&self) -> usize {
        self.cores
    }

    /// Satellites in the share now, this one included. Member files whose owner has gone are removed on the way.
    pub fn members(&self) -> usize {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return 1;
        };
        let mut others = 0;
        for entry in entries.flatten() {
            let path = entry.path();
            let is_member = entry.file_name().to_string_lossy().starts_with("member-");
            if !is_member || path == self.member_path {
                continue;
            }
            let Ok(file) = File::open(&path) else {
                continue;
            };
            match file.try_lock() {
                // Nobody holds it: its satellite has gone. Another member may be removing it too.
                Ok(()) => {
                    let _ = std::fs::remove_file(&path);
                }
                Err(TryLockError::WouldBlock) => others += 1,
                // A lock that cannot be checked is counted: a smaller share is safe, a larger one is not.
                Err(TryLockError::Error(_)) => others += 1,
            }
        }
        others + 1
    }

    /// This member's fair share with `members` in the share, capped at `max_threads`; never below one.
    pub fn fair_share(cores: usize, members: usize, max_threads: usize) -> usize {
        (cores / members.max(1)).min(max_threads).max(1)
    }

    /// Takes up to this member's fair share of cores (at most `max_threads`), waiting while every core is taken.
    /// `None` when `abort` is set before any core came free.
    pub fn acquire(&self, max_threads: usize, abort: &AbortFlag) -> Option<CoreLease> {
        let want = Self::fair_share(self.cores, self.members(), max_threads);
        loop {
            let slots = self.take_free_slots(want);
            if !slots.is_empty() {
                return Some(CoreLease { slots });
            }
            if abort.is_aborted() {
                return None;
            }
            std::thread::sleep(WAIT_STEP);
        }
    }

    /// Locks up to `want` free slot files, starting from this member's first slot.
    fn take_free_slots(&self, want: usize) -> Vec<File> {
        let mut held = Vec::with_capacity(want);
        for i in 0..self.cores {
            if held.len() == want {
                break;
            }
            let path = self
                .dir
                .join(format!("slot-{}", (self.first_slot + i) % self.cores));
            let Ok(file) = OpenOptions::new()
                .create(true)
                .truncate(false)
                .write(true)
                .open(&path)
            else {
                continue;
            };
            if file.try_lock().is_ok() {
                held.push(file);
            }
        }
        held
    }
}

impl Drop for CoreShare {
    fn drop(&mut self) {
        // Leaving cleanly removes the file at once; a killed member's file is removed by the next count.
        let _ = std::fs::remove_file(&self.member_path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn share_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!(
            "whisper-sat-cores-test-{name}-{}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn a_lone_member_may_use_every_core_up_to_its_thread_cap() {
        let dir = share_dir("lone");
        let share = CoreShare::join(&dir, 4).expect("join");
        assert_eq!(share.members(), 1);
        let lease = share.acquire(8, &AbortFlag::new()).expect("lease");
        assert_eq!(lease.threads(), 4);
        drop(lease);
        assert_eq!(
            share
                .acquire(2, &AbortFlag::new())
                .expect("lease")
                .threads(),
            2
        );
    }

    #[test]
    fn members_split_the_cores_and_never_hold_more_than_there_are() {
        let dir = share_dir("split");
        let a = CoreShare::join(&dir, 2).expect("join a");
        let b = CoreShare::join(&dir, 2).expect("join b");
        let c = CoreShare::join(&dir, 2).expect("join c");
        assert_eq!(a.members(), 3);
        let la = a.acquire(2, &AbortFlag::new()).expect("a");
        let lb = b.acquire(2, &AbortFlag::new()).expect("b");
        assert_eq!((la.threads(), lb.threads()), (1, 1));
        // Every core is held: the third waits, and gives up when told to.
        let abort = AbortFlag::new();
        abort.abort();
        assert!(c.acquire(2, &abort).is_none());
        drop(la);
        assert_eq!(c.acquire(2, &AbortFlag::new()).expect("c").threads(), 1);
    }

    #[test]
    fn a_waiting_decode_gets_the_core_as_soon_as_it_is_given_back() {
        let dir = share_dir("wait");
        let a = CoreShare::join(&dir, 1).expect("join a");
        let b = CoreShare::join(&dir, 1).expect("join b");
        let held = a.acquire(1, &AbortFlag::new()).expect("a");
        let (tx, rx) = std::sync::mpsc::channel();
        let waiter = std::thread::spawn(move || {
            let lease = b.acquire(1, &AbortFlag::new()).map(|l| l.threads());
            let _ = tx.send(lease);
        });
        // The waiter cannot have a core while the first lease is held.
        assert!(rx.recv_timeout(Duration::from_millis(50)).is_err());
        drop(held);
        assert_eq!(rx.recv_timeout(Duration::from_secs(10)), Ok(Some(1)));
        waiter.join().expect("waiter");
    }

    #[test]
    fn a_member_that_left_no_longer_counts_and_its_file_is_gone() {
        let dir = share_dir("leave");
        let a = CoreShare::join(&dir, 2).expect("join a");
        let b = CoreShare::join(&dir, 2).expect("join b");
        assert_eq!(a.members(), 2);
        drop(b);
        assert_eq!(a.members(), 1);
        // A member file nobody holds (a satellite killed before it could remove it) is removed by the count.
        let stale = dir.join("member-999999-0");
        std::fs::write(&stale, b"").expect("stale file");
        assert_eq!(a.members(), 1);
        assert!(!stale.exists());
    }

    #[test]
    fn fair_shares_are_at_least_one_and_never_above_the_cap() {
        assert_eq!(CoreShare::fair_share(2, 1, 4), 2);
        assert_eq!(CoreShare::fair_share(2, 3, 4), 1);
        assert_eq!(CoreShare::fair_share(16, 3, 4), 4);
        assert_eq!(CoreShare::fair_share(16, 3, 8), 5);
        assert_eq!(CoreShare::fair_share(4, 0, 4), 4);
    }

    #[test]
    fn a_share_of_no_cores_is_refused() {
        assert!(matches!(
            CoreShare::join(&share_dir("none"), 0),
            Err(CoreShareError::NoCores)
        ));
    }
}
