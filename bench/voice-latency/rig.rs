//! The processes under test: a release `robot-agent` on free ports in a temporary data directory, one
//! `whisper-sat` satellite with the tiny.en model and, for the chat phase, one `llm-sat` with its default model; all
//! killed when the rig is dropped.

use flow::token::{TokenKind, resolve_token};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use anyhow::{Context, bail};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};
use tokio::sync::mpsc;

/// How long the server may take to print its addresses, and the satellite to load its model.
const START_TIMEOUT: Duration = Duration::from_secs(120);

/// Where the release binaries are: `$AGENT_BIN_DIR`, else beside this benchmark's own executable.
pub fn bin_dir() -> anyhow::Result<PathBuf> {
    if let Some(dir) = std::env::var_os("AGENT_BIN_DIR") {
        return Ok(PathBuf::from(dir));
    }
    let exe = std::env::current_exe().context("locating the benchmark executable")?;
    exe.parent()
        .map(Path::to_path_buf)
        .context("the benchmark executable has no directory")
}

fn binary(dir: &Path, name: &str) -> anyhow::Result<PathBuf> {
    let path = dir.join(name);
    if !path.is_file() {
        bail!(
            "{} does not exist: build it first (`cargo build --release -p robot-agent -p whisper-sat -p llm-sat`) \
             or point AGENT_BIN_DIR at the directory holding it",
            path.display()
        );
    }
    Ok(path)
}

/// A running server and satellite.
pub struct Rig {
    agent: Child,
    satellite: Option<Child>,
    llm: Option<Child>,
    data_dir: PathBuf,
    /// `tcp://HOST:PORT` of the hub.
    pub flow_tcp: String,
    pub token: String,
    /// The page's address with its token, as the server printed it (empty if it did not).
    pub page_url: String,
}

impl Rig {
    /// The process ids of the server, the speech satellite and the language model (those of the turn's work).
    pub fn turn_pids(&self) -> Vec<u32> {
        [
            self.agent.id(),
            self.satellite.as_ref().and_then(Child::id),
            self.llm.as_ref().and_then(Child::id),
        ]
        .into_iter()
        .flatten()
        .collect()
    }

    /// Starts the server; the satellite follows with [`Rig::start_satellite`].
    pub async fn start(bins: &Path) -> anyhow::Result<Rig> {
        let data_dir = std::env::temp_dir().join(format!("voice-latency-{}", std::process::id()));
        std::fs::create_dir_all(&data_dir)
            .with_context(|| format!("creating {}", data_dir.display()))?;
        // The shipped brain program (found from the source tree, whatever the working directory); no camera in
        // this benchmark, so the vision module would only idle.
        // The example knowledge folder, as `make run` has it.
        let program = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/brain.tr");
        let knowledge = Path::new(env!("CARGO_MANIFEST_DIR")).join("../knowledge");
        let config = data_dir.join("bench.toml");
        std::fs::write(
            &config,
            format!(
                "[agent]\nknowledge = {:?}\n[modules.brain]\nprogram = {:?}\nchat_thinking_ms = 0\n[modules.vision]\nenabled = false\n",
                knowledge.display().to_string(),
                program.display().to_string()
            ),
        )?;
        let mut agent = Command::new(binary(bins, "robot-agent")?)
            .args(["--http", "127.0.0.1:0", "--flow-tcp", "127.0.0.1:0"])
            .arg("--flow-unix")
            .arg("flow.sock")
            .arg("--data-dir")
            .arg(&data_dir)
            .arg("--config")
            .arg(&config)
            .env("RUST_LOG", "warn")
            .env("NO_COLOR", "1")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .kill_on_drop(true)
            .spawn()
            .context("starting robot-agent")?;
        let mut lines = output_lines(&mut agent);
        // "robot-agent ready: open URL" comes first, then the hub's addresses.
        let mut page_url = String::new();
        let flow_tcp = tokio::time::timeout(START_TIMEOUT, async {
            while let Some(line) = lines.recv().await {
                if let Some(url) = line.strip_prefix("robot-agent ready: open ") {
                    page_url = url.trim().to_owned();
                }
                if let Some(rest) = line.strip_prefix("flow hub: tcp://") {
                    return rest.split_whitespace().next().map(|a| format!("tcp://{a}"));
                }
            }
            None
        })
        .await
        .context("robot-agent did not print its TCP address in time")?
        .context("robot-agent exited at start")?;
        // Keep draining its output so a chatty server never blocks on a full pipe.
        tokio::spawn(async move { while lines.recv().await.is_some() {} });
        let token = resolve_token(None, &data_dir, TokenKind::User)?;
        Ok(Rig {
            agent,
            satellite: None,
            llm: None,
            data_dir,
            flow_tcp,
            token,
            page_url,
        })
    }

    /// Starts `whisper-sat run` with `threads` inference threads, the given hangover and any further arguments.
    pub async fn start_satellite(
        &mut self,
        bins: &Path,
        threads: u32,
        hangover_ms: Option<u32>,
        extra: &[String],
    ) -> anyhow::Result<()> {
        let mut cmd = Command::new(binary(bins, "whisper-sat")?);
        cmd.arg("run")
            .arg("--addr")
            .arg(&self.flow_tcp)
            .arg("--token")
            .arg(&self.token)
            .arg("--name")
            .arg("bench-asr")
            // As `make run` starts its satellite: judging the end of the turn (the default).
            .arg("--threads")
            .arg(threads.to_string());
        if let Some(ms) = hangover_ms {
            cmd.arg("--hangover-ms").arg(ms.to_string());
        }
        cmd.args(extra);
        let child = cmd
            // `VOICE_LATENCY_SATELLITE_LOG=whisper_sat=debug` shows every decode on stderr.
            .env(
                "RUST_LOG",
                std::env::var("VOICE_LATENCY_SATELLITE_LOG").unwrap_or_else(|_| "warn".to_owned()),
            )
            .env("NO_COLOR", "1")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .kill_on_drop(true)
            .spawn()
            .context("starting whisper-sat")?;
        self.satellite = Some(child);
        Ok(())
    }
    /// Stops `whisper-sat`, so that another publisher may own `Agent.transcript` (the knowledge phase types its
    /// questions as final transcripts: a channel has one owner).
    pub async fn stop_satellite(&mut self) -> anyhow::Result<()> {
        if let Some(mut child) = self.satellite.take() {
            child.kill().await.context("stopping whisper-sat")?;
        }
        Ok(())
    }

    /// Starts `llm-sat` with the default model (`make model-llm`) and `threads` generation threads; returns its
    /// process id (for its peak memory at the end).
    pub fn start_llm_sat(&mut self, bins: &Path, threads: u32) -> anyhow::Result<u32> {
        let model = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../models/llm/SmolLM2-135M-Instruct.Q4_1.gguf");
        if !model.is_file() {
            bail!(
                "{} does not exist: provision it first (`make model-llm`)",
                model.display()
            );
        }
        let child = Command::new(binary(bins, "llm-sat")?)
            .arg("--addr")
            .arg(&self.flow_tcp)
            .arg("--token")
            .arg(&self.token)
            .arg("--name")
            .arg("bench-llm")
            .arg("--model")
            .arg(&model)
            .arg("--threads")
            .arg(threads.to_string())
            .env(
                "RUST_LOG",
                std::env::var("VOICE_LATENCY_LLM_LOG").unwrap_or_else(|_| "warn".to_owned()),
            )
            .env("NO_COLOR", "1")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .kill_on_drop(true)
            .spawn()
            .context("starting llm-sat")?;
        let pid = child.id().context("llm-sat exited at start")?;
        self.llm = Some(child);
        Ok(pid)
    }
}

impl Drop for Rig {
    fn drop(&mut self) {
        // The processes die with their handles (kill_on_drop); the data directory goes too.
        drop(self.satellite.take());
        drop(self.llm.take());
        let _ = std::fs::remove_dir_all(&self.data_dir);
    }
}

/// Every line the child prints on stdout or stderr, through one bounded queue (a slow reader only delays the
/// child's logging, never the benchmark's measurements, which do not read it after start).
fn output_lines(child: &mut Child) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel(256);
    if let Some(out) = child.stdout.take() {
        let tx = tx.clone();
        tokio::spawn(async move {
            let mut lines = BufReader::new(out).lines();
            while let Ok(Some(l)) = lines.next_line().await {
                if tx.send(l).await.is_err() {
                    break;
                }
            }
        });
    }
    if let Some(err) = child.stderr.take() {
        tokio::spawn(async move {
            let mut lines = BufReader::new(err).lines();
            while let Ok(Some(l)) = lines.next_line().await {
                if tx.send(l).await.is_err() {
                    break;
                }
            }
        });
    }
    rx
}
