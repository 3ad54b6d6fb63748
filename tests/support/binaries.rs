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

/// Starts `cmd` and returns once it has printed a line starting with `ready` on stdout (within `timeout`), with
/// the rest of its run as a task: it is killed if it has not finished `timeout` after that line.
pub async fn start_when_ready(
    mut cmd: Command,
    ready: &str,
    timeout: Duration,
) -> anyhow::Result<tokio::task::JoinHandle<anyhow::Result<Finished>>> {
    use tokio::io::{AsyncBufReadExt, AsyncReadExt, BufReader};
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .context("spawning")?;
    let stdout = child.stdout.take().context("no stdout")?;
    let mut stderr = child.stderr.take().context("no stderr")?;
    // Read on its own, so that a chatty command never blocks on a full pipe.
    let errors = tokio::spawn(async move {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text).await;
        text
    });
    let mut lines = BufReader::new(stdout).lines();
    let mut printed = String::new();
    let found = tokio::time::timeout(timeout, async {
        while let Some(line) = lines.next_line().await.context("reading stdout")? {
            printed.push_str(&line);
            printed.push('\n');
            if line.starts_with(ready) {
                return anyhow::Ok(true);
            }
        }
        anyhow::Ok(false)
    })
    .await;
    match found {
        Ok(Ok(true)) => {}
        Ok(Ok(false)) => bail!("exited before printing {ready:?}: {printed}"),
        Ok(Err(e)) => return Err(e),
        Err(_) => bail!("printed no {ready:?} within {timeout:?}: {printed}"),
    }
    Ok(tokio::spawn(async move {
        let rest = async {
            while let Some(line) = lines.next_line().await.context("reading stdout")? {
                printed.push_str(&line);
                printed.push('\n');
            }
            anyhow::Ok(child.wait().await?)
        };
        let status = tokio::time::timeout(timeout, rest)
            .await
            .with_context(|| format!("did not finish within {timeout:?}"))??;
        Ok(Finished {
            status,
            stdout: printed,
            stderr: errors.await.unwrap_or_default(),
        })
    }))
}
