//! The pair database: named databases of key -> JSON value, persisted in redb.
//!
//! Every write is its own redb transaction committed with immediate
//! durability (fsync) before the call returns, so an acknowledged write
//! survives a `kill -9` of the server. Methods block on disk I/O; async callers
//! run them on the blocking pool.
//!
//! After an I/O error (a full disk) redb refuses every later call until the
//! database is opened again, so the store closes and reopens it itself at the
//! next call: the failed write is reported to its writer with the reason, and
//! writes succeed again once the disk has room, without a restart.
//!
//! A full disk refuses every write until there is room, and each refusal would log the same warning and the same
//! reopening: the store logs the first at once and then at most one per minute, with the count of those left out.

use std::path::{Path, PathBuf};
use std::sync::{RwLock, RwLockReadGuard};
use std::time::Duration;

use flow::log::Throttle;
use redb::{Database, ReadableTable, TableDefinition};
use thiserror::Error;

/// `(database, key) -> JSON text`.
const VARS: TableDefinition<(&str, &str), &str> = TableDefinition::new("vars");
/// `database -> creation time (s since the epoch)`.
const DATABASES: TableDefinition<&str, u64> = TableDefinition::new("databases");

/// The database every connection starts with.
pub const DEFAULT_DB: &str = "main";

/// How often a failure that repeats on every call (a full disk, a damaged file) is logged at most.
const WARNINGS_EVERY: Duration = Duration::from_secs(60);

#[derive(Debug, Error)]
pub enum PairDbError {
    #[error("no database named {0}")]
    NoDatabase(String),
    #[error("database {0} already exists")]
    Exists(String),
    #[error("storage: {0}")]
    Storage(String),
    /// The disk failed (full, gone): the database is opened again at the next call.
    #[error("storage I/O: {0}")]
    Io(String),
}

/// A redb failure as the store reports it; an I/O failure also marks the database for reopening.
fn storage(e: impl Into<redb::Error>) -> PairDbError {
    let e: redb::Error = e.into();
    if matches!(e, redb::Error::Io(_) | redb::Error::PreviousIo) {
        PairDbError::Io(e.to_string())
    } else {
        PairDbError::Storage(e.to_string())
    }
}

/// Handle on the store; cheap to share behind an `Arc`.
#[derive(Debug)]
pub struct PairDb {
    path: PathBuf,
    /// `None` after an I/O error until a reopen succeeds. Calls share the read lock; a reopen takes the write lock,
    /// so the old handle is gone (redb allows one per file) before the new one opens.
    db: RwLock<Option<Database>>,
    /// The log of I/O failures, of the reopenings after them, and of other storage failures, each held to one line
    /// per interval.
    io_failures: Throttle,
    reopenings: Throttle,
    storage_failures: Throttle,
}

impl PairDb {
    /// Opens (or creates) the store at `path`, with the default database present.
    pub fn open(path: &Path) -> Result<Self, PairDbError> {
        let db = Database::create(path)
            .map_err(|e| PairDbError::Storage(format!("{}: {e}", path.display())))?;
        let this = PairDb {
            path: path.to_path_buf(),
            db: RwLock::new(Some(db)),
            io_failures: Throttle::new(WARNINGS_EVERY),
            reopenings: Throttle::new(WARNINGS_EVERY),
            storage_failures: Throttle::new(WARNINGS_EVERY),
        };
        if !this.exists(DEFAULT_DB)? {
            this.create(DEFAULT_DB)?;
        }
        Ok(this)
    }

    /// Runs `op` on the open database; after an I/O error, closes it so that the next call opens it again. Logs the
    /// storage's failures (the caller's get the reason in their reply), each kind at most once per interval.
    fn with<T>(
        &self,
        op: impl FnOnce(&Database) -> Result<T, PairDbError>,
    ) -> Result<T, PairDbError> {
        let result = {
            let guard = self.handle()?;
            let Some(store) = guard.as_ref() else {
                return Err(PairDbError::Io(
                    "the database is closed after an I/O error".into(),
                ));
            };
            op(store)
        };
        match &result {
            Err(PairDbError::Io(e)) => {
                if let Some(left_out) = self.io_failures.admit() {
                    tracing::warn!(
                        path = %self.path.display(),
                        "pair database: {e}; it is opened again at the next call{left_out}"
                    );
                }
                *self
                    .db
                    .write()
                    .unwrap_or_else(std::sync::PoisonError::into_inner) = None;
            }
            Err(PairDbError::Storage(e)) => {
                if let Some(left_out) = self.storage_failures.admit() {
                    tracing::warn!(path = %self.path.display(), "pair database error: {e}{left_out}");
                }
            }
            _ => {}
        }
        result
    }

    /// The open database, reopening it first if an I/O error closed it.
    fn handle(&self) -> Result<RwLockReadGuard<'_, Option<Database>>, PairDbError> {
        {
            let guard = self
                .db
                .read()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            if guard.is_some() {
                return Ok(guard);
            }
        }
        {
            let mut slot = self
                .db
                .write()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            if slot.is_none() {
                let db = Database::create(&self.path).map_err(|e| {
                    PairDbError::Io(format!(
                        "{} cannot be opened again after an I/O error: {e}",
                        self.path.display()
                    ))
                })?;
                if let Some(left_out) = self.reopenings.admit() {
                    tracing::info!(
                        path = %self.path.display(),
                        "pair database opened again after an I/O error{left_out}"
                    );
                }
                *slot = Some(db);
            }
        }
        Ok(self
            .db
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner))
    }

    pub fn exists(&self, name: &str) -> Result<bool, PairDbError> {
        self.with(|store| {
            let tx = store.begin_read().map_err(storage)?;
            match tx.open_table(DATABASES) {
                Ok(t) => Ok(t.get(name).map_err(storage)?.is_some()),
                Err(redb::TableError::TableDoesNotExist(_)) => Ok(false),
                Err(e) => Err(storage(e)),
            }
        })
    }

    pub fn create(&self, name: &str) -> Result<(), PairDbError> {
        self.with(|store| {
            let tx = store.begin_write().map_err(storage)?;
            {
                let mut t = tx.open_table(DATABASES).map_err(storage)?;
                if t.get(name).map_err(storage)?.is_some() {
                    return Err(PairDbError::Exists(name.into()));
                }
                let now = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map(|d| d.as_secs())
                    .unwrap_or(0);
                t.insert(name, now).map_err(storage)?;
            }
            tx.commit().map_err(storage)
        })
    }

    /// Removes a database and every variable in it.
    pub fn remove(&self, name: &str) -> Result<(), PairDbError> {
        self.with(|store| {
            let tx = store.begin_write().map_err(storage)?;
            {
                let mut dbs = tx.open_table(DATABASES).map_err(storage)?;
                if dbs.remove(name).map_err(storage)?.is_none() {
                    return Err(PairDbError::NoDatabase(name.into()));
                }
                let mut vars = tx.open_table(VARS).map_err(storage)?;
                let keys: Vec<String> = vars
                    .range((name, "")..)
                    .map_err(storage)?
                    .map_while(|entry| {
                        let (k, _) = entry.ok()?;
                        let (db, key) = k.value();
                        (db == name).then(|| key.to_string())
                    })
                    .collect();
                for key in keys {
                    vars.remove((name, key.as_str())).map_err(storage)?;
                }
            }
            tx.commit().map_err(storage)
        })
    }

    pub fn list(&self) -> Result<Vec<String>, PairDbError> {
        self.with(|store| {
            let tx = store.begin_read().map_err(storage)?;
            let t = tx.open_table(DATABASES).map_err(storage)?;
            let mut names = Vec::new();
            for entry in t.iter().map_err(storage)? {
                let (k, _) = entry.map_err(storage)?;
                names.push(k.value().to_string());
            }
            Ok(names)
        })
    }

    /// Stores `json` (already validated) under `key`; durable on return.
    pub fn set(&self, db: &str, key: &str, json: &str) -> Result<(), PairDbError> {
        self.with(|store| {
            let tx = store.begin_write().map_err(storage)?;
            {
                let dbs = tx.open_table(DATABASES).map_err(storage)?;
                if dbs.get(db).map_err(storage)?.is_none() {
                    return Err(PairDbError::NoDatabase(db.into()));
                }
                let mut vars = tx.open_table(VARS).map_err(storage)?;
                vars.insert((db, key), json).map_err(storage)?;
            }
            tx.commit().map_err(storage)
        })
    }

    pub fn get(&self, db: &str, key: &str) -> Result<Option<String>, PairDbError> {
        self.require(db)?;
        self.with(|store| {
            let tx = store.begin_read().map_err(storage)?;
            let vars = match tx.open_table(VARS) {
                Ok(t) => t,
                Err(redb::TableError::TableDoesNotExist(_)) => return Ok(None),
                Err(e) => return Err(storage(e)),
            };
            Ok(vars
                .get((db, key))
                .map_err(storage)?
                .map(|v| v.value().to_string()))
        })
    }

    /// Removes a variable; returns whether it existed.
    pub fn del(&self, db: &str, key: &str) -> Result<bool, PairDbError> {
        self.require(db)?;
        self.with(|store| {
            let tx = store.begin_write().map_err(storage)?;
            let existed = {
                let mut vars = tx.open_table(VARS).map_err(storage)?;
                vars.remove((db, key)).map_err(storage)?.is_some()
            };
            tx.commit().map_err(storage)?;
            Ok(existed)
        })
    }

    pub fn keys(&self, db: &str) -> Result<Vec<String>, PairDbError> {
        self.require(db)?;
        self.with(|store| {
            let tx = store.begin_read().map_err(storage)?;
            let vars = match tx.open_table(VARS) {
                Ok(t) => t,
                Err(redb::TableError::TableDoesNotExist(_)) => return Ok(Vec::new()),
                Err(e) => return Err(storage(e)),
            };
            let mut keys = Vec::new();
            for entry in vars.range((db, "")..).map_err(storage)? {
                let (k, _) = entry.map_err(storage)?;
                let (d, key) = k.value();
                if d != db {
                    break;
                }
                keys.push(key.to_string());
            }
            Ok(keys)
        })
    }

    fn require(&self, db: &str) -> Result<(), PairDbError> {
        if self.exists(db)? {
            Ok(())
        } else {
            Err(PairDbError::NoDatabase(db.into()))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn databases_and_variables() {
        let dir = std::env::temp_dir().join(format!("pairdb-test-{}", std::process::id()));
        let _ = std::fs::remove_file(&dir);
        let db = PairDb::open(&dir).expect("open");
        db.create("robot").expect("create");
        assert!(matches!(db.create("robot"), Err(PairDbError::Exists(_))));
        db.set("robot", "b", "2").expect("set");
        db.set("robot", "a", "{\"x\":1}").expect("set");
        db.set(DEFAULT_DB, "a", "true").expect("set");
        assert_eq!(db.keys("robot").expect("keys"), vec!["a", "b"]);
        assert_eq!(
            db.get("robot", "a").expect("get").as_deref(),
            Some("{\"x\":1}")
        );
        assert!(db.del("robot", "b").expect("del"));
        assert!(!db.del("robot", "b").expect("del"));
        db.remove("robot").expect("remove");
        assert!(matches!(
            db.get("robot", "a"),
            Err(PairDbError::NoDatabase(_))
        ));
        assert_eq!(
            db.get(DEFAULT_DB, "a").expect("get").as_deref(),
            Some("true")
        );
        drop(db);
        let _ = std::fs::remove_file(&dir);
    }

    /// The levels of the events that the pair database logs, in order.
    #[derive(Clone, Default)]
    struct Logged(std::sync::Arc<std::sync::Mutex<Vec<tracing::Level>>>);

    impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for Logged {
        fn on_event(
            &self,
            event: &tracing::Event<'_>,
            _ctx: tracing_subscriber::layer::Context<'_, S>,
        ) {
            if event.metadata().target() == module_path!().trim_end_matches("::tests") {
                self.0
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .push(*event.metadata().level());
            }
        }
    }

    #[test]
    fn a_failing_disk_logs_one_warning_and_one_reopening_not_one_per_refused_write() {
        use tracing_subscriber::layer::SubscriberExt;

        let dir = tempfile::tempdir().expect("temp dir");
        let db = PairDb::open(&dir.path().join("pairs.redb")).expect("open");
        let logged = Logged::default();
        let subscriber = tracing_subscriber::registry().with(logged.clone());
        tracing::subscriber::with_default(subscriber, || {
            // As a full disk fails every write: each call first opens the database again, then fails.
            for _ in 0..10 {
                let refused = db.with(|_| -> Result<(), _> {
                    Err(PairDbError::Io("No space left on device".into()))
                });
                assert!(matches!(refused, Err(PairDbError::Io(_))));
            }
            // The disk has room again: calls succeed, and say nothing.
            db.set(DEFAULT_DB, "k", "1")
                .expect("a write once the disk has room");
        });
        let levels = logged
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone();
        assert_eq!(levels, [tracing::Level::WARN, tracing::Level::INFO]);
        assert_eq!(db.get(DEFAULT_DB, "k").expect("get").as_deref(), Some("1"));
    }
}
