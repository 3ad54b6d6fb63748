//! The `recorder` module: records the session into an MCAP file (the `flow-record` crate, as `flowctl record`
//! does) while the page's holder asks for it (`{"record": true}` / `false` on `Agent.ctrl`) or, with
//! `robot-agent --record FILE`, from start to shutdown. Its state goes out on `Agent.recording`: at each change,
//! and once a second while it records (so a page that opens meanwhile learns it); nothing runs while it is idle.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use agent_contract::channels;
use agent_contract::ctrl::Ctrl;
use agent_contract::recording::RecordingState;
use flow_record::{RecordOptions, Recorder, Selection};
use serde::Deserialize;

use flow_hub::module::{Module, ModuleContext, ModuleFuture};

/// The `recorder` module.
#[derive(Debug, Default)]
pub struct RecorderModule;

/// `[modules.recorder]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct RecorderParams {
    enabled: bool,
    /// Record into this file from the start (what `--record FILE` sets).
    file: Option<String>,
    /// Where recordings asked for by the page go, relative to the data directory.
    dir: String,
    /// Channel globs to record; empty: every stream channel.
    channels: Vec<String>,
}

impl Default for RecorderParams {
    fn default() -> Self {
        RecorderParams {
            enabled: true,
            file: None,
            dir: "recordings".into(),
            channels: Vec::new(),
        }
    }
}

impl RecorderParams {
    /// The checked section and its channel selection, parsed once.
    fn from_json(params: &serde_json::Value) -> anyhow::Result<(Self, Selection)> {
        let p: RecorderParams = serde_path_to_error::deserialize(params)
            .map_err(|e| anyhow::anyhow!("[modules.recorder] {}: {}", e.path(), e.inner()))?;
        let selection = Selection::new(&p.channels)
            .map_err(|e| anyhow::anyhow!("[modules.recorder] channels: {e}"))?;
        if p.dir.is_empty() {
            anyhow::bail!("[modules.recorder] dir: must name a directory");
        }
        Ok((p, selection))
    }
}

fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
}

/// A recording in progress.
struct Running {
    recorder: Recorder,
    file: String,
    started_ms: u64,
}

/// Resolves when the running recording ended by itself; never while none runs.
async fn ended(running: &mut Option<Running>) {
    match running {
        Some(run) => run.recorder.ended().await,
        None => std::future::pending().await,
    }
}

/// What the module does and tells.
struct Desk {
    client: flow::Client,
    channels: Selection,
    dir: PathBuf,
    running: Option<Running>,
    state: RecordingState,
}

impl Desk {
    async fn start(&mut self, file: Option<PathBuf>) {
        if self.running.is_some() {
            return;
        }
        let path = file.unwrap_or_else(|| {
            let stamp = chrono::Local::now().format("session-%Y%m%d-%H%M%S.mcap");
            self.dir.join(stamp.to_string())
        });
        let started = async {
            if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
                std::fs::create_dir_all(parent)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", parent.display()))?;
            }
            let opts = RecordOptions {
                channels: self.channels.clone(),
                ..RecordOptions::default()
            };
            anyhow::Ok(Recorder::start(self.client.clone(), &path, opts).await?)
        };
        let file = path.display().to_string();
        match started.await {
            Ok(recorder) => {
                tracing::info!(file, "recording the session");
                let started_ms = now_ms();
                self.running = Some(Running {
                    recorder,
                    file: file.clone(),
                    started_ms,
                });
                self.state = RecordingState {
                    recording: true,
                    file: Some(file),
                    started_ms: Some(started_ms),
                    messages: 0,
                    error: None,
                };
            }
            Err(e) => {
                tracing::warn!(file, "cannot record: {e:#}");
                self.state.error = Some(format!("cannot record into {file}: {e:#}"));
            }
        }
    }

    async fn stop(&mut self) {
        let Some(run) = self.running.take() else {
            return;
        };
        let (messages, error) = match run.recorder.stop().await {
            // Everything the file holds: the channels' messages and the detections' annotations beside them.
            Ok(report) => (report.messages() + report.annotations, None),
            Err(flow_record::RecordError::Interrupted { path, reason, kept }) => {
                let error = format!(
                    "recording into {path} failed ({reason}); the file keeps the {kept} messages written before"
                );
                tracing::warn!(file = run.file, "{error}");
                (kept, Some(error))
            }
            Err(e) => {
                let error = format!("the recording {} failed: {e}", run.file);
                tracing::warn!(file = run.file, "{error}");
                (0, Some(error))
            }
        };
        tracing::info!(file = run.file, messages, "recording stopped");
        self.state = RecordingState {
            recording: false,
            file: Some(run.file),
            started_ms: Some(run.started_ms),
            messages,
            error,
        };
    }
}

impl Module for RecorderModule {
    fn name(&self) -> &'static str {
        "recorder"
    }

    fn check(&self, params: &serde_json::Value) -> anyhow::Result<()> {
        RecorderParams::from_json(params).map(drop)
    }

    fn run(self: Box<Self>, mut ctx: ModuleContext) -> ModuleFuture {
        Box::pin(async move {
            let (params, channels) = RecorderParams::from_json(&ctx.params)?;
            let client = ctx.client.clone();
            let dir = Path::new(&ctx.config().server.data_dir).join(&params.dir);
            let state = client
                .publisher(channels::RECORDING.name, channels::headers::RECORDING)
                .await?;
            let ctrl = client.subscribe(channels::CTRL.name).await?;
            let first = params.file.clone().map(PathBuf::from);
            let mut desk = Desk {
                client,
                channels,
                dir,
                running: None,
                state: RecordingState {
                    recording: false,
                    file: None,
                    started_ms: None,
                    messages: 0,
                    error: None,
                },
            };
            if first.is_some() {
                desk.start(first).await;
            }
            let mut beat = tokio::time::interval(Duration::from_secs(1));
            beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
            loop {
                let recording = desk.running.is_some();
                tokio::select! {
                    _ = ctx.stopped() => {
                        desk.stop().await;
                        return Ok(());
                    }
                    message = ctrl.recv() => {
                        let Some(message) = message else {
                            desk.stop().await;
                            return Ok(());
                        };
                        let Ok(ctrl) = serde_json::from_slice::<Ctrl>(&message.payload) else { continue };
                        match ctrl.record {
                            Some(true) => desk.start(None).await,
                            Some(false) => desk.stop().await,
                            None => continue,
                        }
                    }
                    _ = beat.tick(), if recording => {}
                    // A write failed (a full disk): say so now, not at the next stop.
                    _ = ended(&mut desk.running), if recording => desk.stop().await,
                }
                let text = serde_json::to_vec(&desk.state).unwrap_or_default();
                // The state is small and comes again; a full send queue only delays it.
                let _ = state.try_publish(text);
            }
        })
    }
}
