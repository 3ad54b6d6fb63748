//! The `Agent.audio.fft` module: a magnitude spectrum of `Agent.audio` every `hop` samples (see `spectrum`).
//!
//! Like `video_y`, it subscribes to its source only while someone subscribes to its output.

use serde::Deserialize;

use super::on_demand;
use super::spectrum::{SpectrumAnalyser, to_le_bytes};
use agent_contract::channels;
use agent_contract::spectrum::MAX_HOP;
use flow_hub::module::{Module, ModuleContext, ModuleFuture, Stopping};

/// The `audio_fft` module.
#[derive(Debug, Default)]
pub struct AudioFft;

/// `[modules.audio_fft]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AudioFftParams {
    pub enabled: bool,
    /// Samples between two spectra (1024 = no overlap), 1..=1024.
    pub hop: usize,
}

impl Default for AudioFftParams {
    fn default() -> Self {
        AudioFftParams {
            enabled: true,
            hop: MAX_HOP,
        }
    }
}

impl AudioFftParams {
    /// Reads and checks `[modules.audio_fft]`; errors say `[modules.audio_fft] KEY: REASON`.
    pub fn from_json(params: &serde_json::Value) -> anyhow::Result<Self> {
        let p: AudioFftParams = serde_path_to_error::deserialize(params)
            .map_err(|e| anyhow::anyhow!("[modules.audio_fft] {}: {}", e.path(), e.inner()))?;
        if !(1..=MAX_HOP).contains(&p.hop) {
            anyhow::bail!(
                "[modules.audio_fft] hop: {} is outside 1..={MAX_HOP}",
                p.hop
            );
        }
        Ok(p)
    }
}

impl Module for AudioFft {
    fn name(&self) -> &'static str {
        "audio_fft"
    }

    fn check(&self, params: &serde_json::Value) -> anyhow::Result<()> {
        AudioFftParams::from_json(params).map(drop)
    }

    fn run(self: Box<Self>, ctx: ModuleContext) -> ModuleFuture {
        Box::pin(async move {
            let hop = AudioFftParams::from_json(&ctx.params)?.hop;
            run(ctx.client.clone(), hop, ctx.stopping()).await;
            Ok(())
        })
    }
}

/// Runs until shutdown.
pub async fn run(client: flow::Client, hop: usize, mut stop: Stopping) {
    let header = channels::headers::audio_fft(hop);
    let Some(publisher) =
        on_demand::output(&client, channels::AUDIO_FFT.name, &header, &mut stop).await
    else {
        return;
    };
    let mut listening = publisher.subscribers();
    loop {
        if !on_demand::until_listened(&mut listening, &mut stop).await {
            return;
        }
        let source = match client.subscribe(channels::AUDIO.name).await {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(error = %e, "cannot subscribe to {}", channels::AUDIO.name);
                return;
            }
        };
        // A fresh analyser per listening period: stale samples from minutes ago must not start the next spectrum.
        let mut analyser = SpectrumAnalyser::new(hop);
        loop {
            tokio::select! {
                () = stop.stopped() => return,
                _ = on_demand::unlistened(&mut listening) => break,
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
