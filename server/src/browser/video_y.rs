//! The `Agent.video.y` module: each `Agent.video` frame as a single-channel JPEG of its Y (luma) channel.
//!
//! It works only while someone subscribes to `Agent.video.y`: with no subscriber it holds no subscription to
//! `Agent.video` and costs nothing. When conversion is slower than the camera it converts the newest frame and
//! skips the rest (counted), so it never builds a backlog.

use std::time::Duration;

use tokio::sync::watch;

use super::channels;
use super::luma::grey_jpeg;

const HEADER: &str = r#"{"format":"jpeg","colour":"grey","width":640,"height":360,"source":"Agent.video"}"#;

pub async fn run(client: flow::Client, quality: u8, mut shutdown: watch::Receiver<bool>) {
    let publisher = loop {
        match client.publisher(channels::VIDEO_Y, HEADER).await {
            Ok(p) => break p,
            Err(e) => {
                tracing::warn!(error = %e, "cannot create {}; retrying", channels::VIDEO_Y);
                tokio::select! {
                    _ = shutdown.changed() => return,
                    _ = tokio::time::sleep(Duration::from_secs(2)) => {}
                }
            }
        }
    };
    let mut listening = publisher.subscribers();
    let mut skipped: u64 = 0;
    let mut failures: u64 = 0;
    loop {
        // Idle until someone subscribes.
        while !*listening.borrow_and_update() {
            tokio::select! {
                _ = shutdown.changed() => return,
                r = listening.changed() => if r.is_err() { return },
            }
        }
        let source = match client.subscribe(channels::VIDEO).await {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(error = %e, "cannot subscribe to {}", channels::VIDEO);
                return;
            }
        };
        tracing::info!("{} has subscribers: converting", channels::VIDEO_Y);
        loop {
            tokio::select! {
                _ = shutdown.changed() => return,
                r = listening.changed() => {
                    if r.is_err() { return }
                    if !*listening.borrow_and_update() { break }
                }
                got = source.recv_latest() => {
                    let Some((data, older)) = got else { return };
                    skipped += older as u64;
                    // Decoding and encoding take milliseconds of CPU: keep them off the async workers.
                    let jpeg = data.payload;
                    let converted = tokio::task::spawn_blocking(move || grey_jpeg(&jpeg, quality)).await;
                    match converted {
                        Ok(Ok(grey)) => {
                            if publisher.publish(grey.jpeg).await.is_err() { return }
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
        tracing::info!(skipped, "{} has no subscribers: idle", channels::VIDEO_Y);
        // `source` drops here: the Agent.video subscription ends.
    }
}
