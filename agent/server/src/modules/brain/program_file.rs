//! The program file: loaded at start (an error there stops the module), then watched once a second and reloaded
//! when it changes (an error then is reported and the running program is kept).

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use agent_brain::{Capabilities, LoadError, Program};

/// What a change of the file led to.
#[derive(Debug)]
pub enum Reload {
    Unchanged,
    Loaded(Program),
    Failed(String),
}

/// The watched program file.
#[derive(Debug)]
pub struct ProgramFile {
    path: PathBuf,
    capabilities: Capabilities,
    /// Modification time and length of the version last read, to notice edits without reading the file.
    stamp: Option<(SystemTime, u64)>,
}

impl ProgramFile {
    pub fn new(path: PathBuf, capabilities: Capabilities) -> Self {
        ProgramFile {
            path,
            capabilities,
            stamp: None,
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Reads and loads the program; the error names the file, line and column.
    pub fn load(&mut self) -> anyhow::Result<Program> {
        self.stamp = self.current_stamp();
        let source = std::fs::read_to_string(&self.path).map_err(|e| {
            anyhow::anyhow!("cannot read the brain program {}: {e}", self.path.display())
        })?;
        Program::load(
            &self.path.display().to_string(),
            &source,
            &self.capabilities,
        )
        .map_err(|e: LoadError| anyhow::anyhow!("{e}"))
    }

    /// Reloads the program if the file changed since it was last read.
    pub fn reload_if_changed(&mut self) -> Reload {
        let stamp = self.current_stamp();
        if stamp.is_none() || stamp == self.stamp {
            // A file that disappeared (an editor replacing it) is retried on the next check.
            return Reload::Unchanged;
        }
        match self.load() {
            Ok(program) => Reload::Loaded(program),
            Err(e) => Reload::Failed(format!("{e:#}")),
        }
    }

    fn current_stamp(&self) -> Option<(SystemTime, u64)> {
        let metadata = std::fs::metadata(&self.path).ok()?;
        Some((metadata.modified().ok()?, metadata.len()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "procedure main { idle: true ~> () }\n";

    #[test]
    fn reloads_on_change_and_reports_errors_with_their_place() -> anyhow::Result<()> {
        let path = std::env::temp_dir().join(format!("brain-file-{}.tr", std::process::id()));
        std::fs::write(&path, GOOD)?;
        let mut file = ProgramFile::new(path.clone(), Capabilities::default());
        assert_eq!(file.load()?.rule_count(), 1);
        assert!(matches!(file.reload_if_changed(), Reload::Unchanged));
        std::fs::write(
            &path,
            "procedure main {\n  idle: true ~> ()\n  talk: heard(T) ++ say(T)\n}\n",
        )?;
        match file.reload_if_changed() {
            Reload::Failed(message) => assert!(
                message.contains(":3:9: unknown predicate `heard`"),
                "{message}"
            ),
            other => panic!("expected a failure, got {other:?}"),
        }
        // The broken version is not reported again until the file changes once more.
        assert!(matches!(file.reload_if_changed(), Reload::Unchanged));
        std::fs::write(
            &path,
            format!("{GOOD}procedure other {{ a: true ~> () }}\n"),
        )?;
        assert!(matches!(file.reload_if_changed(), Reload::Loaded(p) if p.rule_count() == 2));
        std::fs::remove_file(&path)?;
        Ok(())
    }
}
