//! A real `robot-agent` process for integration tests: started on free ports
//! in a temporary data directory, its output collected for assertions, killed
//! (SIGKILL) on drop. The data directory outlives the process, so a test can
//! kill the server and start it again on the same data and ports.

use flow::token::{TokenKind, resolve_token};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, bail};
use flow::{Client, ConnectOptions, FlowAddr};
use tokio::io::{AsyncBufReadExt, AsyncRead, BufReader};
use tokio::process::{Child, Command};
use tokio::sync::Notify;

use crate::binaries::binary;

/// How long a server may take to print its addresses (a cold debug build on a busy machine is slow).
const START_TIMEOUT: Duration = Duration::from_secs(60);

/// A temporary data directory (tokens, pair database, Unix socket).
#[derive(Debug)]
pub struct DataDir {
    dir: tempfile::TempDir,
}

impl DataDir {
    pub fn new() -> anyhow::Result<DataDir> {
        Ok(DataDir {
            dir: tempfile::Builder::new()
                .prefix("agent-test-")
                .tempdir()
                .context("creating a temporary data directory")?,
        })
    }

    /// A data directory inside `parent` (a small disk the test mounted).
    pub fn inside(parent: &Path) -> anyhow::Result<DataDir> {
        Ok(DataDir {
            dir: tempfile::Builder::new()
                .prefix("agent-test-")
                .tempdir_in(parent)
                .context("creating a data directory")?,
        })
    }

    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// The user token the server wrote at first start.
    pub fn token(&self) -> anyhow::Result<String> {
        Ok(resolve_token(None, self.path(), TokenKind::User)?)
    }

    /// The admin token.
    pub fn admin_token(&self) -> anyhow::Result<String> {
        Ok(resolve_token(None, self.path(), TokenKind::Admin)?)
    }

    /// The page token (the credential in the page's URL).
    pub fn page_token(&self) -> anyhow::Result<String> {
        let path = self.path().join("page.token");
        Ok(std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?
            .trim()
            .to_string())
    }
}

/// How to start a server.
#[derive(Debug, Clone, Default)]
pub struct AgentOptions {
    /// Fixed addresses (for a restart on the same ports); free ports when `None`.
    pub http: Option<SocketAddr>,
    pub flow_tcp: Option<SocketAddr>,
    /// Extra configuration (TOML), written to the data directory and passed with `--config`.
    pub config: Option<String>,
    /// `RUST_LOG` for the server (default: `$AGENT_TEST_LOG`, else `info`).
    pub log: Option<String>,
    /// The binary: `robot-agent` (default) or `flow-hub` (the hub alone).
    pub program: Option<&'static str>,
    /// More command-line arguments (e.g. `--record FILE`).
    pub args: Vec<String>,
    /// Run in this network namespace (`ip netns exec`; see `netns::NetnsPair`). Its TCP addresses are then
    /// reachable only from inside it: talk to it over its Unix socket ([`Agent::unix_client`]).
    pub netns: Option<String>,
    /// Start under this open-file limit, soft and hard (`prlimit`), so that the server cannot raise it.
    pub fd_limit: Option<u64>,
    /// More environment variables (e.g. `OTEL_BSP_SCHEDULE_DELAY`).
    pub env: Vec<(String, String)>,
}

/// Everything a process printed, line by line, with a wake-up for waiters.
#[derive(Debug, Default)]
pub struct Output {
    lines: Mutex<Vec<String>>,
    changed: Notify,
}

impl Output {
    fn push(&self, line: String) {
        self.lines
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(line);
        self.changed.notify_waiters();
    }

    /// Every line so far.
    pub fn lines(&self) -> Vec<String> {
        self.lines
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    /// Lines containing `needle`.
    pub fn matching(&self, needle: &str) -> Vec<String> {
        self.lines()
            .into_iter()
            .filter(|l| l.contains(needle))
            .collect()
    }

    /// Waits until at least `count` lines contain `needle`.
    pub async fn wait_for(
        &self,
        needle: &str,
        count: usize,
        timeout: Duration,
    ) -> anyhow::Result<()> {
        let found = tokio::time::timeout(timeout, async {
            loop {
                let notified = self.changed.notified();
                tokio::pin!(notified);
                // Register before looking, so a line pushed in between is not missed.
                notified.as_mut().enable();
                if self.matching(needle).len() >= count {
                    return;
                }
                notified.await;
            }
        })
        .await;
        if found.is_err() {
            bail!(
                "no {count} line(s) containing {needle:?} within {timeout:?}; output so far:\n{}",
                self.lines().join("\n")
            );
        }
        Ok(())
    }
}

/// A running robot-agent, killed with SIGKILL on drop.
#[derive(Debug)]
pub struct Agent {
    child: Child,
    pub http: SocketAddr,
    pub flow_tcp: SocketAddr,
    pub flow_unix: PathBuf,
    pub data_dir: PathBuf,
    pub output: Arc<Output>,
    token: String,
    page_token: String,
}

impl Agent {
    /// Starts a server on free ports in `dir`.
    pub async fn start(dir: &DataDir) -> anyhow::Result<Agent> {
        Self::start_with(dir, AgentOptions::default()).await
    }

    /// Starts the hub alone (`flow-hub`: no agent modules, no page) on free ports in `dir`.
    pub async fn hub(dir: &DataDir) -> anyhow::Result<Agent> {
        Self::hub_with_config(dir, "").await
    }

    /// Starts the hub alone with extra configuration (TOML).
    pub async fn hub_with_config(dir: &DataDir, toml: &str) -> anyhow::Result<Agent> {
        let opts = AgentOptions {
            config: (!toml.is_empty()).then(|| toml.to_string()),
            program: Some("flow-hub"),
            ..AgentOptions::default()
        };
        Self::start_with(dir, opts).await
    }

    /// Starts a server on free ports with extra configuration (TOML).
    pub async fn with_config(dir: &DataDir, toml: &str) -> anyhow::Result<Agent> {
        let opts = AgentOptions {
            config: Some(toml.to_string()),
            ..AgentOptions::default()
        };
        Self::start_with(dir, opts).await
    }

    /// Starts an agent with `config` layered over the defaults and waits until its log shows `ready` (the line a
    /// module prints once it is running), so the test begins with the modules it needs in place.
    pub async fn start_configured(
        dir: &DataDir,
        config: &str,
        ready: &str,
    ) -> anyhow::Result<Agent> {
        let agent = Agent::start_with(
            dir,
            AgentOptions {
                config: Some(config.to_owned()),
                ..AgentOptions::default()
            },
        )
        .await?;
        agent
            .output
            .wait_for(ready, 1, crate::wait::PATIENCE)
            .await?;
        Ok(agent)
    }

    pub async fn start_with(dir: &DataDir, opts: AgentOptions) -> anyhow::Result<Agent> {
        let any = "127.0.0.1:0".to_string();
        let program = opts.program.unwrap_or("robot-agent");
        let mut cmd = match &opts.netns {
            // `ip netns exec` enters the namespace and then executes the binary itself, so the child is the server.
            Some(ns) => {
                let mut cmd = Command::new("ip");
                cmd.args(["netns", "exec", ns]).arg(binary(program)?);
                cmd
            }
            None => match opts.fd_limit {
                Some(limit) => {
                    let mut cmd = Command::new("prlimit");
                    cmd.arg(format!("--nofile={limit}:{limit}"))
                        .arg("--")
                        .arg(binary(program)?);
                    cmd
                }
                None => Command::new(binary(program)?),
            },
        };
        // From the repository root, as `make run` starts it: the default configuration's relative paths (the rule
        // program) resolve there.
        cmd.current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join(".."));
        cmd.arg("--http")
            .arg(opts.http.map_or(any.clone(), |a| a.to_string()))
            .arg("--flow-tcp")
            .arg(opts.flow_tcp.map_or(any, |a| a.to_string()))
            .arg("--flow-unix")
            .arg("flow.sock")
            .arg("--data-dir")
            .arg(dir.path());
        cmd.args(&opts.args);
        if let Some(toml) = &opts.config {
            let path = dir.path().join("test-config.toml");
            std::fs::write(&path, toml).context("writing the test configuration")?;
            cmd.arg("--config").arg(path);
        }
        let mut child = cmd
            .env(
                "RUST_LOG",
                opts.log.clone().unwrap_or_else(|| {
                    std::env::var("AGENT_TEST_LOG").unwrap_or_else(|_| "info".into())
                }),
            )
            .env("NO_COLOR", "1")
            .envs(opts.env.iter().map(|(k, v)| (k.as_str(), v.as_str())))
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .kill_on_drop(true)
            .spawn()
            .context("starting robot-agent")?;
        let output = Arc::new(Output::default());
        let readers: Vec<_> = [
            collect(child.stdout.take(), output.clone()),
            collect(child.stderr.take(), output.clone()),
        ]
        .into_iter()
        .flatten()
        .collect();
        let ready = tokio::select! {
            r = output.wait_for("flow hub: unix:", 1, START_TIMEOUT) => r,
            status = child.wait() => {
                // The process has gone, but its last lines (the error a test reads) may still be in the pipes:
                // drain them before reporting, so the report never races the readers.
                for reader in readers {
                    let _ = tokio::time::timeout(Duration::from_secs(5), reader).await;
                }
                Err(anyhow::anyhow!(
                    "robot-agent exited at start ({status:?}):\n{}", output.lines().join("\n")
                ))
            }
        };
        ready?;
        let lines = output.lines();
        let http = after(&lines, &format!("{program} ready: open "))
            .and_then(|s| s.split_once("://"))
            .and_then(|(_, s)| s.split('/').next())
            .context("no HTTP address printed")?
            .parse()?;
        let flow_tcp = after(&lines, "flow hub: tcp://")
            .and_then(|s| s.split_whitespace().next().map(str::to_string))
            .context("no TCP address printed")?
            .parse()?;
        let flow_unix =
            PathBuf::from(after(&lines, "flow hub: unix:").context("no socket printed")?);
        Ok(Agent {
            child,
            http,
            flow_tcp,
            flow_unix,
            data_dir: dir.path().to_path_buf(),
            output,
            token: dir.token()?,
            page_token: dir.page_token()?,
        })
    }

    pub fn tcp(&self) -> FlowAddr {
        FlowAddr::Tcp(self.flow_tcp.to_string())
    }

    pub fn ws(&self) -> FlowAddr {
        FlowAddr::Ws(format!("ws://{}/flow", self.http))
    }

    pub fn unix(&self) -> FlowAddr {
        FlowAddr::Unix(self.flow_unix.clone())
    }

    pub fn token(&self) -> &str {
        &self.token
    }

    /// The page's URL with `query` (e.g. `"autostart=1"`, or `""`), carrying the page token; the server trades it
    /// for a session cookie and redirects to the same address without it.
    pub fn page_url(&self, query: &str) -> String {
        if query.is_empty() {
            format!("http://{}/?token={}", self.http, self.page_token)
        } else {
            format!("http://{}/?token={}&{query}", self.http, self.page_token)
        }
    }

    /// The page token, for requests that play the page's part (`Authorization: Bearer`).
    pub fn page_token(&self) -> &str {
        &self.page_token
    }

    /// Options for a satellite named `name` that does not reconnect (tests say when they want that).
    pub fn options(&self, name: &str) -> ConnectOptions {
        let mut opts = ConnectOptions::new(name, self.token.clone());
        opts.reconnect = false;
        opts.queue = 4096;
        opts
    }

    /// A logged-in asynchronous satellite over TCP.
    pub async fn client(&self, name: &str) -> anyhow::Result<Client> {
        Ok(Client::connect(&self.tcp(), self.options(name)).await?)
    }

    /// A logged-in asynchronous satellite over the Unix socket (which reaches a server in another network
    /// namespace too).
    pub async fn unix_client(&self, name: &str) -> anyhow::Result<Client> {
        Ok(Client::connect(&self.unix(), self.options(name)).await?)
    }

    /// `flowctl` pointed at this server over TCP, reading the token from the data directory.
    pub fn flowctl(&self) -> anyhow::Result<Command> {
        self.flowctl_at(&self.tcp().to_string())
    }

    /// A microphone stand-in: `flowctl pub-wav Agent.audio WAV --realtime --tail-ms TAIL`, the file streamed in 20 ms
    /// chunks paced in real time, then `tail_ms` of silence so that its last utterance ends.
    pub fn microphone(&self, wav: impl AsRef<Path>, tail_ms: u32) -> anyhow::Result<Command> {
        let mut cmd = self.flowctl()?;
        cmd.arg("pub-wav")
            .arg(agent_contract::channels::AUDIO.name)
            .arg(wav.as_ref())
            .arg("--realtime")
            .arg("--tail-ms")
            .arg(tail_ms.to_string());
        Ok(cmd)
    }

    /// `flowctl --addr ADDR` with this server's data directory.
    pub fn flowctl_at(&self, addr: &str) -> anyhow::Result<Command> {
        let mut cmd = crate::binaries::command("flowctl")?;
        // The caller's environment must not redirect the command elsewhere.
        cmd.env_remove("FLOW_ADDR")
            .env_remove("FLOW_TOKEN")
            .env_remove("ROBOT_AGENT_DATA")
            .arg("--addr")
            .arg(addr)
            .arg("--data-dir")
            .arg(&self.data_dir);
        Ok(cmd)
    }

    /// Kills the server with SIGKILL (no shutdown code runs) and waits for it to be gone.
    pub async fn kill9(mut self) -> anyhow::Result<()> {
        self.child.kill().await.context("killing robot-agent")?;
        Ok(())
    }

    /// Sends SIGTERM (a clean shutdown); [`Agent::wait_exit`] waits for it.
    pub fn terminate(&self) -> anyhow::Result<()> {
        let pid = self.pid().context("robot-agent has exited")?;
        let status = std::process::Command::new("kill")
            .arg("-TERM")
            .arg(pid.to_string())
            .status()
            .context("running kill")?;
        anyhow::ensure!(status.success(), "kill -TERM {pid} failed");
        Ok(())
    }

    /// The server's resident memory now, in kB (`VmRSS`).
    pub fn rss_kb(&self) -> anyhow::Result<u64> {
        let pid = self.pid().context("robot-agent has exited")?;
        let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .context("no VmRSS in /proc/PID/status")
    }

    /// The process id, for signals other than SIGKILL.
    pub fn pid(&self) -> Option<u32> {
        self.child.id()
    }

    /// Waits for the process to exit by itself.
    pub async fn wait_exit(
        &mut self,
        timeout: Duration,
    ) -> anyhow::Result<std::process::ExitStatus> {
        tokio::time::timeout(timeout, self.child.wait())
            .await
            .context("robot-agent did not exit")?
            .context("waiting for robot-agent")
    }
}

fn after<'a>(lines: &'a [String], prefix: &str) -> Option<&'a str> {
    lines.iter().find_map(|l| l.strip_prefix(prefix))
}

/// Copies `stream`'s lines into `output` until it ends; the handle finishes at end of stream.
fn collect(
    stream: Option<impl AsyncRead + Unpin + Send + 'static>,
    output: Arc<Output>,
) -> Option<tokio::task::JoinHandle<()>> {
    let stream = stream?;
    Some(tokio::spawn(async move {
        let mut lines = BufReader::new(stream).lines();
        while let Ok(Some(line)) = lines.next_line().await {
            if std::env::var_os("AGENT_TEST_ECHO").is_some() {
                eprintln!("[robot-agent] {line}");
            }
            output.push(line);
        }
    }))
}
