//! The `flow-hub` process under test, started by the bench on a free loopback port and a Unix socket in a
//! temporary data directory, killed when dropped; and the CPU time of its threads.

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use anyhow::{Context, bail};
use flow::FlowAddr;
use flow::token::{TokenKind, resolve_token};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};

/// A running `flow-hub`.
#[derive(Debug)]
pub struct Hub {
    child: Child,
    pub pid: u32,
    pub tcp: FlowAddr,
    pub unix: FlowAddr,
    pub token: String,
}

/// `$AGENT_BIN_DIR/flow-hub` (as `make bench` sets it), else `flow-hub` beside this binary (same target directory
/// and profile).
pub fn default_bin() -> PathBuf {
    let dir = std::env::var_os("AGENT_BIN_DIR")
        .map(PathBuf::from)
        .or_else(|| {
            std::env::current_exe()
                .ok()
                .and_then(|exe| exe.parent().map(Path::to_path_buf))
        })
        .unwrap_or_default();
    dir.join("flow-hub")
}

/// Starts `bin` with its embedded defaults (plus `config`, a TOML file, if given), a fresh data directory under
/// `work`, a Unix socket there and TCP on a free loopback port, its log in `work/flow-hub.log`.
pub async fn start(bin: &Path, work: &Path, config: Option<&Path>) -> anyhow::Result<Hub> {
    let data = work.join("hub-data");
    std::fs::create_dir_all(&data)?;
    let socket = work.join("flow.sock");
    let log = std::fs::File::create(work.join("flow-hub.log"))?;
    let mut cmd = Command::new(bin);
    cmd.args(["--http", "127.0.0.1:0", "--flow-tcp", "127.0.0.1:0"])
        .arg("--flow-unix")
        .arg(&socket)
        .arg("--data-dir")
        .arg(&data);
    if let Some(config) = config {
        cmd.arg("--config").arg(config);
    }
    let mut child = cmd
        .env("RUST_LOG", "warn")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(log)
        .kill_on_drop(true)
        .spawn()
        .with_context(|| {
            format!(
                "starting {} (build it: cargo build --release -p flow-hub)",
                bin.display()
            )
        })?;
    let pid = child.id().context("flow-hub exited at once")?;
    let stdout = child.stdout.take().context("flow-hub stdout")?;
    let mut lines = BufReader::new(stdout).lines();
    let wait_ready = async {
        let (mut tcp, mut unix) = (None, None);
        while let Some(line) = lines.next_line().await? {
            if let Some(rest) = line.strip_prefix("flow hub: tcp://") {
                tcp = rest.split_whitespace().next().map(str::to_string);
            } else if let Some(rest) = line.strip_prefix("flow hub: unix:") {
                unix = Some(PathBuf::from(rest.trim()));
            }
            if let (Some(tcp), Some(unix)) = (&tcp, &unix) {
                return Ok((tcp.clone(), unix.clone()));
            }
        }
        bail!("flow-hub exited before it was ready (see its log)")
    };
    let (tcp, unix) = tokio::time::timeout(Duration::from_secs(30), wait_ready)
        .await
        .context("flow-hub did not print its addresses within 30 s")??;
    // Keep reading stdout so that the hub never blocks on a full pipe.
    tokio::spawn(async move { while let Ok(Some(_)) = lines.next_line().await {} });
    let token = resolve_token(None, &data, TokenKind::User)?;
    Ok(Hub {
        child,
        pid,
        tcp: FlowAddr::Tcp(tcp),
        unix: FlowAddr::Unix(unix),
        token,
    })
}

impl Hub {
    /// Whether the process is still running.
    pub fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    pub async fn stop(mut self) {
        let _ = self.child.start_kill();
        let _ = tokio::time::timeout(Duration::from_secs(5), self.child.wait()).await;
    }
}

/// CPU nanoseconds of `pid`'s threads (the benches' shared reading of `/proc`).
pub use agent_bench::cpu_ns;
