//! `flowctl record` as a child process for the recording tests and benchmark, and the two readers a recording
//! is checked with: the crate's own lenient reader and the Python `mcap` package (the reader Foxglove's tooling
//! shares), run from the Python SDK's virtual environment.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use anyhow::{Context, bail};
use flow_record::{Entry, RecordedChannel, RecordedMessage, RecordingReader};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::Child;

use crate::agent::Agent;

/// A running `flowctl record`, killed on drop.
#[derive(Debug)]
pub struct RecordProcess {
    pub child: Child,
    pub path: PathBuf,
}

impl RecordProcess {
    /// Starts `flowctl record -o PATH ARGS...` against `agent` and waits until it has subscribed to what exists.
    pub async fn start(agent: &Agent, path: &Path, args: &[&str]) -> anyhow::Result<RecordProcess> {
        let mut cmd = agent.flowctl()?;
        cmd.arg("record")
            .arg("-o")
            .arg(path)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().context("starting flowctl record")?;
        let stderr = child.stderr.take().context("no stderr")?;
        let mut lines = BufReader::new(stderr).lines();
        let ready = tokio::time::timeout(crate::satellite::SATELLITE_PATIENCE, async {
            while let Some(line) = lines.next_line().await? {
                if line.starts_with("recording to ") {
                    return anyhow::Ok(());
                }
                eprintln!("[flowctl record] {line}");
            }
            bail!("flowctl record exited before it was recording")
        })
        .await
        .context("flowctl record did not start")?;
        ready?;
        // Keep draining stderr so that the process never blocks on a full pipe.
        tokio::spawn(async move {
            while let Ok(Some(line)) = lines.next_line().await {
                eprintln!("[flowctl record] {line}");
            }
        });
        Ok(RecordProcess {
            child,
            path: path.to_path_buf(),
        })
    }

    /// The process id, for signals.
    pub fn pid(&self) -> anyhow::Result<u32> {
        self.child.id().context("flowctl record has exited")
    }

    /// Ctrl-C: the recorder finishes the file (summary, footer) and prints its report, which this returns.
    pub async fn interrupt(self) -> anyhow::Result<String> {
        let pid = self.pid()?;
        let status = std::process::Command::new("kill")
            .arg("-INT")
            .arg(pid.to_string())
            .status()
            .context("running kill")?;
        anyhow::ensure!(status.success(), "kill -INT {pid} failed");
        self.wait_exit().await
    }

    /// Waits for the recorder to exit (after a signal, or by itself when the hub goes away) and returns its report.
    pub async fn wait_exit(mut self) -> anyhow::Result<String> {
        let mut stdout = self.child.stdout.take().context("no stdout")?;
        let mut out = String::new();
        // Its report is read to the end of its output, which comes when it exits: one bound for both.
        let status = tokio::time::timeout(crate::satellite::SATELLITE_PATIENCE, async {
            tokio::io::AsyncReadExt::read_to_string(&mut stdout, &mut out).await?;
            self.child.wait().await
        })
        .await
        .context("flowctl record did not exit")??;
        anyhow::ensure!(
            status.success(),
            "flowctl record exited with {status}: {out}"
        );
        Ok(out)
    }

    /// SIGKILL: no code of the recorder runs any more.
    pub async fn kill9(mut self) -> anyhow::Result<()> {
        self.child.kill().await.context("killing flowctl record")
    }
}

/// What the crate's lenient reader found in a file.
#[derive(Debug, Default)]
pub struct Contents {
    pub channels: BTreeMap<u16, RecordedChannel>,
    pub messages: Vec<RecordedMessage>,
    pub truncated: Option<String>,
}

impl Contents {
    /// The messages recorded on a topic, in file order.
    pub fn on(&self, topic: &str) -> Vec<&RecordedMessage> {
        self.messages
            .iter()
            .filter(|m| {
                self.channels
                    .get(&m.channel)
                    .is_some_and(|c| c.topic == topic)
            })
            .collect()
    }

    /// The channels recorded for a topic.
    pub fn channels_of(&self, topic: &str) -> Vec<&RecordedChannel> {
        self.channels
            .values()
            .filter(|c| c.topic == topic)
            .collect()
    }
}

/// Reads a recording, complete or cut short, with the crate's reader.
pub fn read(path: &Path) -> anyhow::Result<Contents> {
    let mut contents = Contents::default();
    let mut reader = RecordingReader::open(path)?;
    while let Some(entry) = reader.next_entry()? {
        match entry {
            Entry::Channel(c) => {
                contents.channels.insert(c.id, c);
            }
            Entry::Message(m) => contents.messages.push(m),
        }
    }
    contents.truncated = reader.truncated().map(str::to_string);
    Ok(contents)
}

/// The Python SDK's virtual environment's interpreter; a missing one is an error that says how to make it.
pub fn python() -> anyhow::Result<PathBuf> {
    let python =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../satellites/python/.venv/bin/python");
    if !python.is_file() {
        bail!(
            "{} is missing: the recording tests check files with the Python mcap package; \
             run `make python` (scripts/python-sdk.sh) first",
            python.display()
        );
    }
    Ok(python)
}

/// Reads a recording with the Python `mcap` package (`tests/mcap_check.py`): `indexed` through the summary
/// (`make_reader`), `stream` from start to end tolerating a cut. Returns the script's JSON report.
pub async fn python_check(path: &Path, mode: &str) -> anyhow::Result<serde_json::Value> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("mcap_check.py");
    let mut cmd = tokio::process::Command::new(python()?);
    cmd.arg(script).arg(path).arg(mode).kill_on_drop(true);
    let out = crate::binaries::run(cmd, b"", Duration::from_secs(120))
        .await?
        .ok()
        .context(
            "the Python mcap reader failed (is `mcap` installed? run scripts/python-sdk.sh)",
        )?;
    serde_json::from_str(out.trim()).with_context(|| format!("not JSON: {out}"))
}
