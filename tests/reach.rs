//! Reach and endurance through a real robot-agent: the page over HTTPS from another address gets the microphone
//! and camera; strangers never keep a satellite out; idle HTTP connections under a small descriptor limit leave
//! the hub working; the pair database and the recorder survive a full disk; a logged-in client's unfinished frame
//! has a deadline; logs go to stderr and a clean shutdown is quiet.
//!
//! The full-disk tests mount a small tmpfs, which needs root (as CI runs): elsewhere they say so and stop.

use std::net::{IpAddr, SocketAddr};
use std::path::{Path, PathBuf};
use std::time::Duration;

use agent_tests::browser_chromium::{Chromium, Devices};
use agent_tests::browser_link::LINK_ONLY_CONFIG;
use agent_tests::http::request;
use agent_tests::{Agent, AgentOptions, DataDir, PATIENCE, RawConn, recv_until, until};
use anyhow::{Context, bail, ensure};
use serde_json::json;
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;

const PAGE_READY: Duration = Duration::from_secs(40);

/// This machine's first IPv4 address that is not loopback, if it has one.
fn outside_address() -> Option<IpAddr> {
    let out = std::process::Command::new("hostname")
        .arg("-I")
        .output()
        .ok()?;
    String::from_utf8_lossy(&out.stdout)
        .split_whitespace()
        .filter_map(|a| a.parse::<IpAddr>().ok())
        .find(|ip| ip.is_ipv4() && !ip.is_loopback())
}

/// A bare `flow-hub` (no agent modules), with `config` layered over the defaults.
async fn bare_hub(data: &DataDir, config: Option<&str>) -> anyhow::Result<Agent> {
    Agent::start_with(
        data,
        AgentOptions {
            program: Some("flow-hub"),
            config: config.map(str::to_string),
            ..Default::default()
        },
    )
    .await
}

/// Runs a shell pipeline and returns its trimmed output.
fn sh(script: &str) -> anyhow::Result<String> {
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg(script)
        .output()
        .context("running sh")?;
    ensure!(
        out.status.success(),
        "{script}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// The page on `host` with its credential, in kiosk mode (microphone and camera start on their own).
fn page_at(scheme: &str, host: IpAddr, agent: &Agent) -> String {
    format!(
        "{scheme}://{host}:{}/?token={}&autostart=1&aec=0",
        agent.http.port(),
        agent.page_token()
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_opened_over_https_from_another_address_gets_the_microphone_and_camera()
-> anyhow::Result<()> {
    let Some(outside) = outside_address() else {
        bail!("this machine has no non-loopback IPv4 address to open the page by");
    };
    let media_dir = tempfile::Builder::new().prefix("https-media-").tempdir()?;
    let media = agent_tests::browser_media::prepare(media_dir.path())?.0;
    let all = "0.0.0.0:0".parse::<SocketAddr>()?;

    // Plain HTTP from another address: the browser refuses the devices and the page says why.
    let plain_dir = DataDir::new()?;
    let plain = Agent::start_with(
        &plain_dir,
        AgentOptions {
            http: Some(all),
            config: Some(LINK_ONLY_CONFIG.into()),
            ..Default::default()
        },
    )
    .await?;
    let browser = Chromium::launch_with(&Devices::Granted(media.clone())).await?;
    let tab = browser.open(&page_at("http", outside, &plain)).await?;
    browser
        .wait_for(
            &tab,
            "document.getElementById('notice').textContent.includes('https')",
            PAGE_READY,
        )
        .await
        .context("over plain http the page should explain that it needs https")?;
    browser.quit().await;
    drop(plain);

    // HTTPS with the certificate made for this machine.
    let data = DataDir::new()?;
    let agent = Agent::start_with(
        &data,
        AgentOptions {
            http: Some(all),
            config: Some(LINK_ONLY_CONFIG.into()),
            args: vec!["--https".into()],
            ..Default::default()
        },
    )
    .await?;
    let cert = data.path().join("tls/cert.pem");
    let cert = cert.display();
    // The fingerprint printed beside the URL is the certificate's.
    let printed = agent
        .output
        .matching("certificate SHA-256")
        .first()
        .and_then(|l| {
            l.split("SHA-256 ")
                .nth(1)
                .map(str::trim)
                .map(str::to_string)
        })
        .context("no fingerprint printed")?;
    let actual = sh(&format!(
        "openssl x509 -in {cert} -noout -fingerprint -sha256"
    ))?;
    ensure!(
        actual.ends_with(&printed),
        "printed {printed}, openssl says {actual}"
    );
    ensure!(
        !agent.output.matching("ready: open https://").is_empty(),
        "the printed address is https"
    );
    let names = sh(&format!(
        "openssl x509 -in {cert} -noout -ext subjectAltName"
    ))?;
    ensure!(
        names.contains(&outside.to_string()),
        "the certificate names {outside}: {names}"
    );
    // The browser trusts exactly this certificate's key, as a user who compared the fingerprint and accepted it.
    let spki = sh(&format!(
        "openssl x509 -in {cert} -noout -pubkey | openssl pkey -pubin -outform der | openssl dgst -sha256 -binary | base64"
    ))?;
    let flag = format!("--ignore-certificate-errors-spki-list={spki}");
    let browser =
        Chromium::launch_with_flags(&Devices::Granted(media.clone()), &[flag.as_str()]).await?;
    let tab = browser.open(&page_at("https", outside, &agent)).await?;
    browser
        .wait_for(
            &tab,
            "window.isSecureContext && location.protocol === 'https:' && window.agentDebug && \
             agentDebug.role === 'holder' && agentDebug.sent.video > 0 && agentDebug.sent.audio > 0",
            PAGE_READY,
        )
        .await
        .context("over https the page should stream the microphone and camera")?;
    // What it sends reaches the hub.
    let client = agent.client("listener").await?;
    let audio = client
        .subscribe(agent_contract::channels::AUDIO.name)
        .await?;
    tokio::time::timeout(PATIENCE, audio.recv())
        .await
        .context("no microphone audio reached the hub")?
        .context("subscription ended")?;
    browser.quit().await;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_satellite_logs_in_while_two_hundred_strangers_hold_connections() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let agent = agent_tests::browser_link::start_link_only(&data).await?;
    // 150 FlowProtocol connections that never log in, 25 `/flow` WebSockets that never log in, 25 idle HTTP
    // connections: more than the 64 places loopback strangers have.
    let mut strangers = Vec::new();
    for _ in 0..150 {
        strangers.push(TcpStream::connect(agent.flow_tcp).await?);
    }
    let mut sockets = Vec::new();
    for _ in 0..25 {
        let url = format!("ws://{}/flow", agent.http);
        if let Ok((ws, _)) = tokio_tungstenite::connect_async(url.as_str()).await {
            sockets.push(ws);
        }
    }
    for _ in 0..25 {
        strangers.push(TcpStream::connect(agent.http).await?);
    }
    // Satellites with the token get in at once, over TCP and over the Unix socket, while the strangers wait.
    for i in 0..5 {
        let client = tokio::time::timeout(PATIENCE, agent.client(&format!("satellite-{i}")))
            .await
            .context("login timed out")?
            .with_context(|| format!("satellite {i} was kept out by strangers"))?;
        client.var_set("seen", &json!(i)).await?;
        let unix = agent.unix_client(&format!("local-{i}")).await?;
        drop((client, unix));
    }
    let status = request(agent.http, "GET", "/healthz", &[]).await?;
    ensure!(status.status == 200, "/healthz answered {}", status.status);
    // Evictions are logged once per address and interval, not once per connection.
    agent
        .output
        .wait_for("closed before login", 1, PATIENCE)
        .await?;
    let warned = agent.output.matching("closed before login").len();
    ensure!(
        warned <= 3,
        "{warned} eviction lines for one address: {:?}",
        agent.output.matching("closed before login")
    );
    ensure!(
        agent.output.matching("refusing connection").is_empty(),
        "a newcomer was refused"
    );
    drop((strangers, sockets));
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_http_connections_under_a_small_descriptor_limit_leave_login_and_healthz_working()
-> anyhow::Result<()> {
    let data = DataDir::new()?;
    let agent = Agent::start_with(
        &data,
        AgentOptions {
            config: Some(LINK_ONLY_CONFIG.into()),
            fd_limit: Some(1024),
            ..Default::default()
        },
    )
    .await?;
    let pid = agent.pid().context("no pid")?;
    let limits = std::fs::read_to_string(format!("/proc/{pid}/limits"))?;
    ensure!(
        limits
            .lines()
            .any(|l| l.starts_with("Max open files") && l.contains("1024")),
        "the server runs under 1024 descriptors: {limits}"
    );
    let mut idle = Vec::new();
    for _ in 0..1100 {
        idle.push(TcpStream::connect(agent.http).await?);
    }
    tokio::time::sleep(Duration::from_millis(500)).await;
    let open = std::fs::read_dir(format!("/proc/{pid}/fd"))?.count();
    ensure!(
        open < 900,
        "{open} descriptors open with 1100 idle connections"
    );
    let health = request(agent.http, "GET", "/healthz", &[]).await?;
    ensure!(health.status == 200, "/healthz answered {}", health.status);
    let client = tokio::time::timeout(PATIENCE, agent.client("satellite"))
        .await
        .context("login timed out")??;
    client.var_set("alive", &json!(true)).await?;
    ensure!(
        agent.output.matching("Too many open files").len() <= 3,
        "the log floods: {:?}",
        agent.output.matching("Too many open files")
    );
    drop(idle);
    Ok(())
}

/// A tmpfs of `size` mounted on a fresh directory, unmounted on drop; `None` (with the reason printed) where
/// mounting is not allowed.
struct Tmpfs(tempfile::TempDir);

impl Tmpfs {
    fn mount(size: &str) -> anyhow::Result<Option<Tmpfs>> {
        let dir = tempfile::Builder::new().prefix("full-disk-").tempdir()?;
        let status = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir.path())
            .stderr(std::process::Stdio::null())
            .status()?;
        if !status.success() {
            eprintln!("SKIPPED: mounting a tmpfs needs root (CI runs as root)");
            return Ok(None);
        }
        Ok(Some(Tmpfs(dir)))
    }

    fn path(&self) -> &Path {
        self.0.path()
    }

    /// Writes a file until the disk is full.
    fn fill(&self) -> anyhow::Result<PathBuf> {
        let filler = self.path().join("filler");
        let mut f = std::fs::File::create(&filler)?;
        let block = vec![0x55u8; 64 * 1024];
        loop {
            use std::io::Write;
            if let Err(e) = f.write_all(&block) {
                ensure!(
                    e.raw_os_error() == Some(28),
                    "filling failed otherwise: {e}"
                );
                break;
            }
        }
        Ok(filler)
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg("-l")
            .arg(self.0.path())
            .status();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_pair_database_takes_writes_again_once_a_full_disk_has_room() -> anyhow::Result<()> {
    let Some(disk) = Tmpfs::mount("4m")? else {
        return Ok(());
    };
    let data = DataDir::inside(disk.path())?;
    let agent = bare_hub(&data, None).await?;
    ensure!(
        data.path().join("pairs.redb").exists(),
        "the pair database is on the small disk"
    );
    let client = agent.client("writer").await?;
    client.var_set("before", &json!("kept")).await?;
    let filler = disk.fill()?;
    // Writes fail with the reason while the disk is full, and the earlier one is kept.
    let big = json!("x".repeat(200_000));
    let mut refused = None;
    for i in 0..20 {
        if let Err(e) = client.var_set(&format!("during{i}"), &big).await {
            refused = Some(e.to_string());
            break;
        }
    }
    let refused = refused.context("no write failed on a full disk")?;
    ensure!(
        refused.contains("disk") || refused.contains("space"),
        "the refusal says why: {refused}"
    );
    // Room again: writes succeed without a restart, and everything acknowledged is there.
    std::fs::remove_file(&filler)?;
    let mut ok = false;
    for _ in 0..20 {
        if client.var_set("after", &json!("written")).await.is_ok() {
            ok = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    ensure!(
        ok,
        "the pair database did not take writes again once the disk had room"
    );
    ensure!(client.var_get("before").await? == Some(json!("kept")));
    ensure!(client.var_get("after").await? == Some(json!("written")));
    agent
        .output
        .wait_for("opened again after an I/O error", 1, PATIENCE)
        .await?;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recording_on_a_full_disk_says_so_and_leaves_a_readable_mcap() -> anyhow::Result<()> {
    let Some(disk) = Tmpfs::mount("2m")? else {
        return Ok(());
    };
    let data = DataDir::new()?;
    let file = disk.path().join("session.mcap");
    let agent = Agent::start_with(
        &data,
        AgentOptions {
            config: Some(LINK_ONLY_CONFIG.into()),
            args: vec!["--record".into(), file.display().to_string()],
            ..Default::default()
        },
    )
    .await?;
    let client = agent.client("camera").await?;
    let state = client
        .subscribe(agent_contract::channels::RECORDING.name)
        .await?;
    let publisher = client.publisher("Test.noise", "{}").await?;
    // Incompressible camera-sized frames at 30 fps (about 1 MB/s) fill the 2 MB disk within a few seconds, after
    // the recorder has written a chunk or two (it closes one a second).
    let mut failed = None;
    for _ in 0..2000u32 {
        let noise: Vec<u8> = (0..32 * 1024).map(|_| rand::random::<u8>()).collect();
        publisher.publish(noise).await?;
        tokio::time::sleep(Duration::from_millis(33)).await;
        while let Some(m) = state.try_recv() {
            let s: agent_contract::recording::RecordingState = serde_json::from_slice(&m.payload)?;
            if !s.recording && s.error.is_some() {
                failed = Some(s);
            }
        }
        if failed.is_some() {
            break;
        }
    }
    let failed = match failed {
        Some(s) => s,
        None => recv_until(
            &state,
            "a failed recording",
            PATIENCE,
            |m| match serde_json::from_slice::<agent_contract::recording::RecordingState>(
                &m.payload,
            ) {
                Ok(s) if !s.recording && s.error.is_some() => Some(Ok(s)),
                Ok(_) => None,
                Err(e) => Some(Err(e)),
            },
        )
        .await
        .context("Agent.recording never said the recording failed")??,
    };
    let error = failed.error.unwrap_or_default();
    ensure!(
        error.contains("space") || error.contains("28"),
        "the error names the cause: {error}"
    );
    agent
        .output
        .wait_for("failed", 1, PATIENCE)
        .await
        .context("no WARN in the log")?;
    ensure!(
        agent
            .output
            .lines()
            .iter()
            .any(|l| l.contains("WARN") && l.contains("session.mcap")),
        "the failure is a WARN naming the file"
    );
    // The file opens, through its summary-less end, with what was written.
    let contents = agent_tests::recording::read(&file)?;
    ensure!(
        contents.truncated.is_none(),
        "the file ends cleanly: {:?}",
        contents.truncated
    );
    ensure!(
        !contents.on("Test.noise").is_empty(),
        "it keeps the messages written before the disk filled"
    );
    ensure!(
        failed.messages as usize >= contents.on("Test.noise").len(),
        "the state counts what the file keeps ({} vs {})",
        failed.messages,
        contents.on("Test.noise").len()
    );
    let python = agent_tests::recording::python_check(&file, "stream").await?;
    ensure!(
        python["messages"].as_u64().unwrap_or(0) > 0,
        "the Python mcap reader reads it: {python}"
    );
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_logged_in_client_that_stops_mid_frame_is_closed_at_the_frame_deadline()
-> anyhow::Result<()> {
    let data = DataDir::new()?;
    let agent = bare_hub(&data, Some("[hub]\nframe_timeout_ms = 1000\n")).await?;
    let mut conn = RawConn::login(agent.flow_tcp, agent.token(), false).await?;
    // The start of a 1 MB frame, and nothing more.
    let mut head = (1u32 << 20).to_le_bytes().to_vec();
    head.extend_from_slice(&[0x01; 100]);
    conn.send_bytes(&head).await?;
    conn.expect_closed(PATIENCE).await?;
    agent
        .output
        .wait_for("hub.frame_timeout_ms", 1, PATIENCE)
        .await?;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn logs_go_to_stderr_and_a_clean_shutdown_is_quiet() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let bin = agent_tests::binary("robot-agent")?;
    let mut child = tokio::process::Command::new(bin)
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join(".."))
        .args(["--http", "127.0.0.1:0", "--flow-tcp", "127.0.0.1:0"])
        .arg("--data-dir")
        .arg(data.path())
        .arg("--config")
        .arg({
            let p = data.path().join("c.toml");
            std::fs::write(&p, LINK_ONLY_CONFIG)?;
            p
        })
        .env("RUST_LOG", "info")
        .env("NO_COLOR", "1")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .kill_on_drop(true)
        .spawn()?;
    let mut stdout = child.stdout.take().context("stdout")?;
    let mut stderr = child.stderr.take().context("stderr")?;
    let out_task = tokio::spawn(async move {
        let mut s = String::new();
        tokio::io::AsyncReadExt::read_to_string(&mut stdout, &mut s)
            .await
            .map(|_| s)
    });
    let err_task = tokio::spawn(async move {
        let mut s = String::new();
        tokio::io::AsyncReadExt::read_to_string(&mut stderr, &mut s)
            .await
            .map(|_| s)
    });
    // Let the modules start, then stop it as an operator's Ctrl-C or a service manager does.
    tokio::time::sleep(Duration::from_secs(3)).await;
    let pid = child.id().context("exited early")?;
    std::process::Command::new("kill")
        .args(["-TERM", &pid.to_string()])
        .status()?;
    let status = tokio::time::timeout(PATIENCE, child.wait()).await??;
    ensure!(status.success(), "exit status {status}");
    // Its output ends with it (unless something it started still holds the pipes): read within the bound.
    let out = tokio::time::timeout(PATIENCE, out_task)
        .await
        .context("stdout did not end")???;
    let err = tokio::time::timeout(PATIENCE, err_task)
        .await
        .context("stderr did not end")???;
    ensure!(out.contains("ready: open"), "stdout has the address: {out}");
    ensure!(
        !out.contains("INFO") && !out.contains("WARN"),
        "no log lines on stdout: {out}"
    );
    ensure!(
        err.contains("robot-agent is up"),
        "the log is on stderr: {err}"
    );
    let warnings: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("WARN") || l.contains("ERROR"))
        .collect();
    ensure!(warnings.is_empty(), "a clean shutdown warns: {warnings:#?}");
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_text_message_on_the_flow_websocket_closes_it_with_a_code_and_a_warning()
-> anyhow::Result<()> {
    use futures_util::{SinkExt, StreamExt};
    use tokio_tungstenite::tungstenite::Message;
    let data = DataDir::new()?;
    let agent = bare_hub(&data, None).await?;
    let url = format!("ws://{}/flow", agent.http);
    let (mut ws, _) = tokio_tungstenite::connect_async(url.as_str()).await?;
    ws.send(Message::Text("hello".into())).await?;
    let mut code = None;
    until("the WebSocket to close", PATIENCE, async {
        while let Ok(Some(msg)) = tokio::time::timeout(PATIENCE, ws.next()).await {
            match msg {
                Ok(Message::Close(frame)) => {
                    code = frame.map(|f| u16::from(f.code));
                    break;
                }
                Ok(_) => {}
                Err(_) => break,
            }
        }
    })
    .await?;
    ensure!(
        code == Some(1003),
        "closed with {code:?}, not 1003 (unsupported data)"
    );
    agent
        .output
        .wait_for("killing spurious client", 1, PATIENCE)
        .await?;
    let mut s = TcpStream::connect(agent.http).await?;
    s.shutdown().await?;
    Ok(())
}
