//! Drives Debian's headless Chromium for the browser tests over the Chrome DevTools Protocol (CDP).
//!
//! CDP is the protocol WebDriver implementations and playwright themselves use underneath; speaking it directly
//! over one WebSocket (tokio-tungstenite, already in the workspace) needs no driver binary of a matching version
//! and no browser download. Chromium runs with fake media devices fed from files, so the page's real capture path
//! (getUserMedia, AudioWorklet, canvas JPEG encoding) runs on recorded fixtures.

use std::collections::HashMap;
use std::path::PathBuf;
use std::process::Stdio;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, anyhow, bail};
use base64::Engine;
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};
use tokio::sync::{mpsc, oneshot};
use tokio_tungstenite::tungstenite::Message;

/// What the fake microphone and camera play (both loop).
#[derive(Debug, Clone)]
pub struct FakeMedia {
    pub audio_wav: PathBuf,
    pub video_y4m: PathBuf,
}

/// The media devices the browser offers the page.
#[derive(Debug, Clone)]
pub enum Devices {
    /// Fake microphone and camera playing files; permission granted without a prompt.
    Granted(FakeMedia),
    /// Fake devices exist, but the user refuses permission (headless Chromium denies the prompt).
    Denied,
    /// No microphone or camera at all; permission would be granted.
    Absent,
}

type Pending = Arc<Mutex<HashMap<u64, oneshot::Sender<Result<Value, String>>>>>;

/// A running headless Chromium and its DevTools connection; killed on drop with every process it started, and its
/// profile removed.
#[derive(Debug)]
pub struct Chromium {
    child: Child,
    out: mpsc::Sender<String>,
    pending: Pending,
    next_id: AtomicU64,
    /// The browser's process group (its pid), killed whole on drop.
    group: Option<u32>,
    _profile: tempfile::TempDir,
}

/// One tab, attached with a flat CDP session.
#[derive(Debug, Clone)]
pub struct Tab {
    pub target_id: String,
    session_id: String,
}

impl Chromium {
    /// Starts `chromium` (or `$CHROMIUM`) headless with fake media devices playing `media`.
    pub async fn launch(media: &FakeMedia) -> anyhow::Result<Chromium> {
        Self::launch_with(&Devices::Granted(media.clone())).await
    }

    /// Starts `chromium` (or `$CHROMIUM`) headless offering `devices` to pages.
    pub async fn launch_with(devices: &Devices) -> anyhow::Result<Chromium> {
        Self::launch_with_flags(devices, &[]).await
    }

    /// As [`Chromium::launch_with`], with `extra` command-line switches after the usual ones (a later
    /// `--window-size` wins; `--disable-3d-apis` takes WebGL away; `--enable-unsafe-swiftshader` keeps software
    /// WebGL, which Chromium otherwise only falls back to with a deprecation warning).
    pub async fn launch_with_flags(devices: &Devices, extra: &[&str]) -> anyhow::Result<Chromium> {
        let exe = std::env::var("CHROMIUM").unwrap_or_else(|_| "chromium".into());
        let profile = tempfile::Builder::new()
            .prefix("agent-chromium-")
            .tempdir()?;
        let mut child = Command::new(&exe)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-background-networking",
                "--no-first-run",
                "--no-default-browser-check",
                "--disable-background-timer-throttling",
                "--disable-renderer-backgrounding",
                "--disable-backgrounding-occluded-windows",
                "--autoplay-policy=no-user-gesture-required",
                "--window-size=1400,860",
                "--remote-debugging-port=0",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .args(device_flags(devices))
            .args(extra)
            .arg("about:blank")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            // Its own process group: the renderers and the crash handler go with it, instead of writing into the
            // profile after it was removed (which left `agent-chromium-*` folders behind in the temporary folder).
            .process_group(0)
            .kill_on_drop(true)
            .spawn()
            .with_context(|| format!("starting {exe} (apt-get install chromium)"))?;
        let group = child.id();
        let stderr = child.stderr.take().context("chromium stderr")?;
        let url = devtools_url(stderr).await?;
        let (ws, _) = tokio_tungstenite::connect_async(url.as_str())
            .await
            .context("connecting to DevTools")?;
        let (mut sink, mut stream) = ws.split();
        let (out, mut out_rx) = mpsc::channel::<String>(64);
        tokio::spawn(async move {
            while let Some(text) = out_rx.recv().await {
                if sink.send(Message::Text(text.into())).await.is_err() {
                    break;
                }
            }
        });
        let pending: Pending = Arc::default();
        let routes = pending.clone();
        tokio::spawn(async move {
            while let Some(Ok(msg)) = stream.next().await {
                let Message::Text(text) = msg else { continue };
                let Ok(v) = serde_json::from_str::<Value>(text.as_str()) else {
                    continue;
                };
                // Events carry no id; only replies are routed.
                let Some(id) = v.get("id").and_then(Value::as_u64) else {
                    continue;
                };
                let tx = routes.lock().unwrap_or_else(|p| p.into_inner()).remove(&id);
                if let Some(tx) = tx {
                    let result = match v.get("error") {
                        Some(e) => Err(e.to_string()),
                        None => Ok(v.get("result").cloned().unwrap_or(Value::Null)),
                    };
                    let _ = tx.send(result);
                }
            }
        });
        Ok(Chromium {
            child,
            out,
            pending,
            next_id: AtomicU64::new(1),
            group,
            _profile: profile,
        })
    }

    async fn command(
        &self,
        session: Option<&str>,
        method: &str,
        params: Value,
    ) -> anyhow::Result<Value> {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let mut msg = json!({"id": id, "method": method, "params": params});
        if let Some(s) = session {
            msg["sessionId"] = json!(s);
        }
        let (tx, rx) = oneshot::channel();
        self.pending
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(id, tx);
        self.out
            .send(msg.to_string())
            .await
            .map_err(|_| anyhow!("DevTools connection closed"))?;
        let reply = tokio::time::timeout(Duration::from_secs(30), rx)
            .await
            .map_err(|_| anyhow!("{method}: no reply within 30 s"))?
            .map_err(|_| anyhow!("{method}: DevTools connection closed"))?;
        reply.map_err(|e| anyhow!("{method}: {e}"))
    }

    /// Opens `url` in a new tab.
    pub async fn open(&self, url: &str) -> anyhow::Result<Tab> {
        let created = self
            .command(None, "Target.createTarget", json!({"url": url}))
            .await?;
        let target_id = created["targetId"]
            .as_str()
            .context("createTarget: no targetId")?
            .to_string();
        let attached = self
            .command(
                None,
                "Target.attachToTarget",
                json!({"targetId": target_id, "flatten": true}),
            )
            .await?;
        let session_id = attached["sessionId"]
            .as_str()
            .context("attachToTarget: no sessionId")?
            .to_string();
        Ok(Tab {
            target_id,
            session_id,
        })
    }

    /// Evaluates `expression` in the tab (promises are awaited) and returns its JSON value.
    pub async fn eval(&self, tab: &Tab, expression: &str) -> anyhow::Result<Value> {
        let r = self
            .command(
                Some(&tab.session_id),
                "Runtime.evaluate",
                json!({"expression": expression, "returnByValue": true, "awaitPromise": true}),
            )
            .await?;
        if let Some(ex) = r.get("exceptionDetails") {
            bail!("page threw evaluating {expression:?}: {ex}");
        }
        Ok(r["result"].get("value").cloned().unwrap_or(Value::Null))
    }

    /// Polls `expression` every 100 ms until it is `true`, for at most `timeout`.
    pub async fn wait_for(
        &self,
        tab: &Tab,
        expression: &str,
        timeout: Duration,
    ) -> anyhow::Result<()> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            // Early in a page's life the hook may not exist yet: an exception is "not yet".
            if let Ok(Value::Bool(true)) = self.eval(tab, expression).await {
                return Ok(());
            }
            if tokio::time::Instant::now() >= deadline {
                bail!("timed out after {timeout:?} waiting for `{expression}`");
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// A PNG screenshot of the tab.
    pub async fn screenshot(&self, tab: &Tab) -> anyhow::Result<Vec<u8>> {
        let r = self
            .command(
                Some(&tab.session_id),
                "Page.captureScreenshot",
                json!({"format": "png"}),
            )
            .await?;
        let data = r["data"].as_str().context("captureScreenshot: no data")?;
        Ok(base64::engine::general_purpose::STANDARD.decode(data)?)
    }

    /// A PNG screenshot of the part of the tab that the first element matching CSS `selector` covers.
    pub async fn screenshot_of(&self, tab: &Tab, selector: &str) -> anyhow::Result<Vec<u8>> {
        let sel = serde_json::to_string(selector)?;
        let rect = self
            .eval(
                tab,
                &format!(
                    "(() => {{ const r = document.querySelector({sel}).getBoundingClientRect(); \
                     return [r.x, r.y, r.width, r.height]; }})()"
                ),
            )
            .await?;
        let r: Vec<f64> = serde_json::from_value(rect).context("element rectangle")?;
        anyhow::ensure!(
            r.len() == 4 && r[2] > 0.0 && r[3] > 0.0,
            "{selector} has no area: {r:?}"
        );
        let clip = json!({"x": r[0], "y": r[1], "width": r[2], "height": r[3], "scale": 1});
        let shot = self
            .command(
                Some(&tab.session_id),
                "Page.captureScreenshot",
                json!({"format": "png", "clip": clip}),
            )
            .await?;
        let data = shot["data"]
            .as_str()
            .context("captureScreenshot: no data")?;
        Ok(base64::engine::general_purpose::STANDARD.decode(data)?)
    }

    /// Closes a tab (its page unloads: sockets close, devices stop).
    pub async fn close(&self, tab: &Tab) -> anyhow::Result<()> {
        self.command(
            None,
            "Target.closeTarget",
            json!({"targetId": tab.target_id}),
        )
        .await
        .map(drop)
    }

    /// The browser's process id (its renderers, GPU and utility processes are its descendants), while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.child.id()
    }

    /// Stops the browser.
    pub async fn quit(mut self) {
        let _ = self.child.kill().await;
    }
}

impl Drop for Chromium {
    /// Kills the browser's whole process group, then removes its profile, trying again for a second while the last
    /// of its processes let go of it.
    fn drop(&mut self) {
        if let Some(pid) = self.group {
            let _ = std::process::Command::new("kill")
                .args(["-KILL", "--", &format!("-{pid}")])
                .stderr(Stdio::null())
                .status();
        }
        let profile = self._profile.path();
        for _ in 0..20 {
            if std::fs::remove_dir_all(profile).is_ok() || !profile.exists() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

fn device_flags(devices: &Devices) -> Vec<String> {
    match devices {
        Devices::Granted(media) => vec![
            "--use-fake-ui-for-media-stream".into(),
            "--use-fake-device-for-media-stream".into(),
            format!(
                "--use-file-for-fake-audio-capture={}",
                media.audio_wav.display()
            ),
            format!(
                "--use-file-for-fake-video-capture={}",
                media.video_y4m.display()
            ),
        ],
        Devices::Denied => vec!["--use-fake-device-for-media-stream".into()],
        Devices::Absent => vec!["--use-fake-ui-for-media-stream".into()],
    }
}

/// How long Chromium may take to start and print its DevTools address.
const DEVTOOLS_PATIENCE: Duration = Duration::from_secs(120);

/// Reads Chromium's stderr until it prints its DevTools address; keeps draining it afterwards.
async fn devtools_url(stderr: tokio::process::ChildStderr) -> anyhow::Result<String> {
    let mut lines = BufReader::new(stderr).lines();
    // A cold start on a busy two-core machine (SwiftShader, a detector and Whisper at work) has taken over 30 s.
    let found = tokio::time::timeout(DEVTOOLS_PATIENCE, async {
        while let Ok(Some(line)) = lines.next_line().await {
            if let Some(pos) = line.find("ws://") {
                return Some(line[pos..].trim().to_string());
            }
        }
        None
    })
    .await
    .map_err(|_| anyhow!("chromium printed no DevTools address within {DEVTOOLS_PATIENCE:?}"))?;
    let url = found.context("chromium exited before printing its DevTools address")?;
    // A full stderr pipe would block the browser: keep reading it.
    tokio::spawn(async move { while let Ok(Some(_)) = lines.next_line().await {} });
    Ok(url)
}
