//! Finding the workspace's built binaries and running them with a deadline.

use std::path::PathBuf;
use std::process::Stdio;
use std::time::Duration;

use anyhow::{Context, bail};
use tokio::io::AsyncWriteExt;
use tokio::process::Command;

/// The path of a binary built from this workspace.
///
/// `$AGENT_BIN_DIR/NAME` if set, else `NAME` in the profile directory of the
/// running test (tests run from `target/<profile>/deps`). `cargo test` does not
/// build other packages' binaries, so they must be built first: `make test`
/// does; by hand, `cargo build -p robot-agent -p flowctl -p flow-examples`.
pub fn binary(name: &str) -> anyhow::Result<PathBuf> {
    let dir = match std::env::var_os("AGENT_BIN_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => {
            let exe = std::env::current_exe().context("locating the test executable")?;
            exe.parent()
                .and_then(|deps| deps.parent())
                .map(PathBuf::from)
                .context("the test executable has no target directory")?
        }
    };
    let path = dir.join(name);
    if !path.is_file() {
        bail!(
            "{} does not exist: build the binaries before the tests \
             (`cargo build -p robot-agent -p flowctl -p flow-examples`, with the same \
             profile and CARGO_TARGET_DIR; `make test` does this) or set AGENT_BIN_DIR",
            path.display()
        );
    }
    Ok(path)
}

/// What a finished command printed.
#[derive(Debug)]
pub struct Finished {
    pub status: std::process::ExitStatus,
    pub stdout: String,
    pub stderr: String,
}

impl Finished {
    pub fn success(&self) -> bool {
        self.status.success()
    }

    /// Stdout, failing with everything printed if the command did not succeed.
    pub fn ok(self) -> anyhow::Result<String> {
        if !self.status.success() {
            bail!(
                "exited with {}\nstdout:\n{}\nstderr:\n{}",
                self.status,
                self.stdout,
                self.stderr
            );
        }
        Ok(self.stdout)
    }
}

/// Runs `cmd` to completion with `stdin` as input, killing it after `timeout`.
pub async fn run(mut cmd: Command, stdin: &[u8], timeout: Duration) -> anyhow::Result<Finished> {
    let mut child = cmd
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .context("spawning")?;
    let input = child.stdin.take();
    let finished = async {
        if let Some(mut input) = input {
            input.write_all(stdin).await.context("writing stdin")?;
            // Dropping the handle closes stdin: the command sees end of input.
        }
        anyhow::Ok(child.wait_with_output().await?)
    };
    let out = tokio::time::timeout(timeout, finished)
        .await
        .with_context(|| format!("did not finish within {timeout:?}"))??;
    Ok(Finished {
        status: out.status,
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    })
}

/// A `Command` for a workspace binary, with colours off.
pub fn command(name: &str) -> anyhow::Result<Command> {
    let mut cmd = Command::new(binary(name)?);
    cmd.env("NO_COLOR", "1").kill_on_drop(true);
    Ok(cmd)
}
