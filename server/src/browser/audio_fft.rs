//! The `Agent.audio.fft` module: a magnitude spectrum of `Agent.audio` every `hop` samples (see `spectrum`).
//!
//! Like `video_y`, it subscribes to its source only while someone subscribes to its output.

use std::time::Duration;

use tokio::sync::watch;

use super::channels;
use super::spectrum::{BINS, FFT_SIZE, SpectrumAnalyser, to_le_bytes};

pub async fn run(client: flow::Client, hop: usize, mut shutdown: watch::Receiver<bool>) {
    let header = serde_json::json!({
        "format": "f32le", "size": FFT_SIZE, "bins": BINS, "rate": 22050, "window": "hann", "hop": hop,
        "scale": "linear, full-scale sine = 1.0",
    })
    .to_string();
    let publisher = loop {
        match client.publisher(channels::AUDIO_FFT, &header).await {
            Ok(p) => break p,
            Err(e) => {
                tracing::warn!(error = %e, "cannot create {}; retrying", channels::AUDIO_FFT);
                tokio::select! {
                    _ = shutdown.changed() => return,
                    _ = tokio::time::sleep(Duration::from_secs(2)) => {}
                }
            }
        }
    };
    let mut listening = publisher.subscribers();
    loop {
        while !*listening.borrow_and_update() {
            tokio::select! {
                _ = shutdown.changed() => return,
                r = listening.changed() => if r.is_err() { return },
            }
        }
        let source = match client.subscribe(channels::AUDIO).await {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(error = %e, "cannot subscribe to {}", channels::AUDIO);
                return;
            }
        };
        // A fresh analyser per listening period: stale samples from minutes ago must not start the next spectrum.
        let mut analyser = SpectrumAnalyser::new(hop);
        loop {
            tokio::select! {
                _ = shutdown.changed() => return,
                r = listening.changed() => {
                    if r.is_err() { return }
                    if !*listening.borrow_and_update() { break }
                }
                got = source.recv() => {
                    let Some(data) = got else { return };
                    let mut spectra = Vec::new();
                    analyser.push_pcm(&data.payload, |m| spectra.push(to_le_bytes(m)));
                    for s in spectra {
                        // try_publish: a spectrum is only worth sending now; if the hub link is full, skip it.
                        if publisher.try_publish(s).is_err() { return }
                    }
                }
            }
        }
    }
}
