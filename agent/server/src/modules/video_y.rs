//! The `Agent.video.y` module: each `Agent.video` frame as a single-channel JPEG of its Y (luma) channel.
//!
//! It works only while someone subscribes to `Agent.video.y`: with no subscriber it holds no subscription to
//! `Agent.video` and costs nothing. When conversion is slower than the camera it converts the newest frame and
//! skips the rest (counted), so it never builds a backlog.

use std::time::Instant;

use serde::Deserialize;
use serde_json::json;

use super::luma::grey_jpeg;
use super::on_demand;
use agent_contract::channels;
use flow_hub::module::{Module, ModuleContext, ModuleFuture, Stopping};

/// The `video_y` module.
#[derive(Debug, Default)]
pub struct VideoY;

/// `[modules.video_y]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VideoYParams {
    pub enabled: bool,
    /// JPEG quality of the grey frames, 1..=100.
    pub quality: u8,
}

impl Default for VideoYParams {
    fn default() -> Self {
        VideoYParams {
            enabled: true,
            quality: 80,
        }
    }
}

impl VideoYParams {
    /// Reads and checks `[modules.video_y]`; errors say `[modules.video_y] KEY: REASON`.
    pub fn from_json(params: &serde_json::Value) -> anyhow::Result<Self> {
        let p: VideoYParams = serde_path_to_error::deserialize(params)
            .map_err(|e| anyhow::anyhow!("[modules.video_y] {}: {}", e.path(), e.inner()))?;
        if !(1..=100).contains(&p.quality) {
            anyhow::bail!(
                "[modules.video_y] quality: {} is outside 1..=100",
                p.quality
            );
        }
        Ok(p)
    }
}

impl Module for VideoY {
    fn name(&self) -> &'static str {
        "video_y"
    }

    fn check(&self, params: &serde_json::Value) -> anyhow::Result<()> {
        VideoYParams::from_json(params).map(drop)
    }

    fn run(self: Box<Self>, ctx: ModuleContext) -> ModuleFuture {
        Box::pin(async move {
            let quality = VideoYParams::from_json(&ctx.params)?.quality;
            let (client, stop) = (ctx.client.clone(), ctx.stopping());
            run(client, quality, stop, move |figures| ctx.report(figures)).await;
            Ok(())
        })
    }
}

/// Conversion figures, reported at `/api/status` every this many frames.
const REPORT_EVERY: u64 = 30;

/// Runs until shutdown; `report` receives the conversion figures now and then.
pub async fn run(
    client: flow::Client,
    quality: u8,
    mut stop: Stopping,
    report: impl Fn(serde_json::Value),
) {
    let Some(publisher) = on_demand::output(
        &client,
        channels::VIDEO_Y.name,
        channels::headers::VIDEO_Y,
        &mut stop,
    )
    .await
    else {
        return;
    };
    let mut listening = publisher.subscribers();
    let mut skipped: u64 = 0;
    let mut failures: u64 = 0;
    let mut converted: u64 = 0;
    let mut busy_us: u64 = 0;
    loop {
        // Idle until someone subscribes.
        if !on_demand::until_listened(&mut listening, &mut stop).await {
            return;
        }
        let source = match client.subscribe(channels::VIDEO.name).await {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(error = %e, "cannot subscribe to {}", channels::VIDEO.name);
                return;
            }
        };
        tracing::info!("{} has subscribers: converting", channels::VIDEO_Y.name);
        loop {
            tokio::select! {
                () = stop.stopped() => return,
                _ = on_demand::unlistened(&mut listening) => break,
                got = source.recv_latest() => {
                    let Some((data, older)) = got else { return };
                    skipped += older as u64;
                    // Decoding and encoding take milliseconds of CPU: keep them off the async workers.
                    let jpeg = data.payload;
                    let started = Instant::now();
                    let result = tokio::task::spawn_blocking(move || grey_jpeg(&jpeg, quality)).await;
                    busy_us += started.elapsed().as_micros() as u64;
                    match result {
                        Ok(Ok(grey)) => {
                            if publisher.publish(grey.jpeg).await.is_err() { return }
                            converted += 1;
                            if converted.is_multiple_of(REPORT_EVERY) {
                                report(json!({
                                    "converted": converted, "skipped": skipped, "failed": failures,
                                    "mean_ms": busy_us as f64 / 1000.0 / converted as f64,
                                }));
                            }
                        }
                        Ok(Err(e)) => {
                            failures += 1;
                            if failures.is_power_of_two() {
                                tracing::warn!(error = %e, failures, "video frame not converted");
                            }
                        }
                        Err(e) => tracing::error!(error = %e, "conversion task failed"),
                    }
                }
            }
        }
        tracing::info!(
            skipped,
            "{} has no subscribers: idle",
            channels::VIDEO_Y.name
        );
        // `source` drops here: the Agent.video subscription ends.
    }
}
