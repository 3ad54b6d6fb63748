//! The two server processes under test, started by the bench itself on free
//! loopback ports: `robot-agent` (our hub) and Debian's `redis-server`. Both
//! are killed when their handle is dropped.

use flow::token::{TokenKind, resolve_token};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use anyhow::{Context, bail};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};

/// A running server process.
#[derive(Debug)]
pub struct Server {
    child: Child,
    pub pid: u32,
}

impl Server {
    /// Peak resident set size since start or the last [`Server::reset_peak`], in bytes.
    pub fn peak_rss(&self) -> Option<u64> {
        proc_status_kb(self.pid, "VmHWM:").map(|kb| kb * 1024)
    }

    /// Resets the kernel's peak-RSS mark to the current RSS (writing 5 to
    /// `clear_refs`), so the next [`Server::peak_rss`] covers one configuration.
    /// Returns false where the kernel refuses; the peak then covers the whole run.
    pub fn reset_peak(&self) -> bool {
        std::fs::write(format!("/proc/{}/clear_refs", self.pid), "5").is_ok()
    }

    /// Current resident set size in bytes.
    pub fn rss(&self) -> Option<u64> {
        proc_status_kb(self.pid, "VmRSS:").map(|kb| kb * 1024)
    }

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

fn proc_status_kb(pid: u32, key: &str) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    line[key.len()..]
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()
}

/// A `robot-agent` serving only loopback ports chosen by the kernel.
#[derive(Debug)]
pub struct Agent {
    pub server: Server,
    pub flow_tcp: String,
    pub token: String,
}

/// The built-in modules, all switched off by [`HUB_ONLY`].
const MODULES: [&str; 6] = ["browser", "video_y", "audio_fft", "tts", "brain", "vision"];

/// Starts `robot-agent` with its embedded default configuration, a fresh data
/// directory under `work`, and logs in `work/robot-agent.log`. With
/// `hub_only`, every built-in module is switched off, so that the peak RSS is
/// the hub's own and not that of OpenCV's cascades or espeak's voice data.
/// `io_threads`, when given, overrides the hub's `hub.io_threads`.
pub async fn start_agent(
    bin: &Path,
    work: &Path,
    hub_only: bool,
    io_threads: Option<usize>,
) -> anyhow::Result<Agent> {
    let data = work.join("agent-data");
    std::fs::create_dir_all(&data)?;
    let mut text = String::new();
    if let Some(n) = io_threads {
        text.push_str(&format!("[hub]\nio_threads = {n}\n"));
    }
    if hub_only {
        for m in MODULES {
            text.push_str(&format!("[modules.{m}]\nenabled = false\n"));
        }
    }
    let mut config_args: Vec<std::ffi::OsString> = Vec::new();
    if !text.is_empty() {
        let path = work.join("bench.toml");
        std::fs::write(&path, text)?;
        config_args.push("--config".into());
        config_args.push(path.into_os_string());
    }
    let log = std::fs::File::create(work.join("robot-agent.log"))?;
    let mut child = Command::new(bin)
        .args(["--http", "127.0.0.1:0", "--flow-tcp", "127.0.0.1:0"])
        .args(["--flow-unix", ""])
        .args(&config_args)
        .arg("--data-dir")
        .arg(&data)
        .env("RUST_LOG", "warn")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(log)
        .kill_on_drop(true)
        .spawn()
        .with_context(|| format!("starting {}", bin.display()))?;
    let pid = child.id().context("robot-agent exited at once")?;
    let stdout = child.stdout.take().context("robot-agent stdout")?;
    let mut lines = BufReader::new(stdout).lines();
    let wait_ready = async {
        while let Some(line) = lines.next_line().await? {
            if let Some(rest) = line.strip_prefix("flow hub: tcp://") {
                let addr = rest.split_whitespace().next().unwrap_or_default();
                return Ok(addr.to_string());
            }
        }
        bail!("robot-agent exited before it was ready (see its log)")
    };
    let flow_tcp = tokio::time::timeout(Duration::from_secs(30), wait_ready)
        .await
        .context("robot-agent did not print its flow address within 30 s")??;
    // Keep reading stdout so the server can never block on a full pipe.
    tokio::spawn(async move { while let Ok(Some(_)) = lines.next_line().await {} });
    let token = resolve_token(None, &data, TokenKind::User)?;
    Ok(Agent {
        server: Server { child, pid },
        flow_tcp,
        token,
    })
}

/// A `redis-server` on a free loopback port.
#[derive(Debug)]
pub struct Redis {
    pub server: Server,
    pub url: String,
}

/// Starts `redis-server` without persistence (no RDB snapshots, no AOF), on
/// loopback only, otherwise with its stock settings (including the pub/sub
/// client output buffer limit of 32 MB hard, 8 MB for 60 s).
pub async fn start_redis(bin: &Path, work: &Path) -> anyhow::Result<Redis> {
    let port = free_port()?;
    let log = std::fs::File::create(work.join("redis-server.log"))?;
    let child = Command::new(bin)
        .args(["--port", &port.to_string(), "--bind", "127.0.0.1"])
        .args(["--save", "", "--appendonly", "no", "--daemonize", "no"])
        .args(["--loglevel", "warning", "--logfile", ""])
        .arg("--dir")
        .arg(work)
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .kill_on_drop(true)
        .spawn()
        .with_context(|| {
            format!(
                "starting {} (Debian package redis-server; `make deps` installs it)",
                bin.display()
            )
        })?;
    let pid = child.id().context("redis-server exited at once")?;
    let url = format!("redis://127.0.0.1:{port}/");
    let client = redis::Client::open(url.as_str())?;
    for _ in 0..100 {
        if let Ok(mut conn) = client.get_multiplexed_async_connection().await
            && redis::cmd("PING")
                .query_async::<String>(&mut conn)
                .await
                .is_ok()
        {
            return Ok(Redis {
                server: Server { child, pid },
                url,
            });
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    bail!("redis-server did not answer PING on port {port} within 5 s")
}

/// A loopback port nobody listens on right now.
fn free_port() -> anyhow::Result<u16> {
    let listener = std::net::TcpListener::bind("127.0.0.1:0")?;
    Ok(listener.local_addr()?.port())
}

/// `robot-agent` built next to this binary (same target directory and profile).
pub fn default_agent_bin() -> PathBuf {
    std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|dir| dir.join("robot-agent")))
        .unwrap_or_else(|| PathBuf::from("robot-agent"))
}
