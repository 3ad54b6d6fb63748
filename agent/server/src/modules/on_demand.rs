//! Helpers for modules that work only while their output channel has subscribers (`video_y`, `audio_fft`).

use std::time::Duration;

use flow_hub::module::Stopping;
use tokio::sync::watch;

/// Creates the module's output channel, retrying every 2 s (the hub may still be starting); `None` at shutdown.
pub async fn output(
    client: &flow::Client,
    name: &str,
    header: &str,
    stop: &mut Stopping,
) -> Option<flow::Publisher> {
    loop {
        match client.publisher(name, header).await {
            Ok(p) => return Some(p),
            Err(e) => {
                tracing::warn!(error = %e, "cannot create {name}; retrying");
                tokio::select! {
                    () = stop.stopped() => return None,
                    _ = tokio::time::sleep(Duration::from_secs(2)) => {}
                }
            }
        }
    }
}

/// Waits until someone subscribes; false at shutdown.
pub async fn until_listened(listening: &mut watch::Receiver<bool>, stop: &mut Stopping) -> bool {
    while !*listening.borrow_and_update() {
        tokio::select! {
            () = stop.stopped() => return false,
            r = listening.changed() => if r.is_err() { return false },
        }
    }
    true
}

/// Resolves when the last subscriber leaves (or the channel is gone).
pub async fn unlistened(listening: &mut watch::Receiver<bool>) {
    loop {
        if listening.changed().await.is_err() || !*listening.borrow_and_update() {
            return;
        }
    }
}
