//! The `echo` module: `Agent.audio` less the agent's own voice, on `Agent.audio.clean` (docs/voice.md, "Echo
//! cancellation").
//!
//! One canceller per microphone, in the server, before voice activity: every whisper satellite (here or on another
//! machine) subscribes to the cleaned stream and none pays for the cancelling. The far-end reference is
//! `Agent.speech` placed where the page plays it (`agent_echo::reference`): its `Agent.playback` reports when it
//! has them, a jitter buffer after the first chunk otherwise; `speech_stop` on `Agent.avatar` ends what was sent
//! ahead. Like `audio_fft`, it subscribes to its sources only while someone subscribes to its output; the
//! reference is read before the microphone when both are ready, so a frame never misses speech already sent.

use std::time::{Duration, Instant};

use agent_contract::avatar::AvatarCommand;
use agent_contract::channels;
use agent_contract::say::PlaybackStarted;
use agent_echo::{Canceller, CancellerConfig};
use flow_hub::module::{Module, ModuleContext, ModuleFuture};
use serde::Deserialize;

use super::on_demand;

/// The `echo` module.
#[derive(Debug, Default)]
pub struct EchoModule;

/// `[modules.echo]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EchoParams {
    pub enabled: bool,
    /// How far ahead of the microphone the reference is fed (ms, 0..=200).
    pub lead_ms: u32,
    /// The page's jitter buffer, for speech the page has not reported playing (ms, 0..=1000).
    pub jitter_ms: u32,
    /// Silence what the adaptive filter leaves of the echo (`agent_echo::residual`).
    pub residual_gate: bool,
    /// The agent's speech a new stream hears before deciding it has no echo; until then frames under the agent's
    /// level are held (ms, 0..=10000).
    pub hold_ms: u32,
}

impl Default for EchoParams {
    fn default() -> Self {
        let cfg = CancellerConfig::default();
        EchoParams {
            enabled: true,
            lead_ms: cfg.lead_ms,
            jitter_ms: cfg.jitter_ms,
            residual_gate: cfg.residual_gate,
            hold_ms: cfg.hold_ms,
        }
    }
}

impl EchoParams {
    /// Reads and checks `[modules.echo]`; errors say `[modules.echo] KEY: REASON`.
    pub fn from_json(params: &serde_json::Value) -> anyhow::Result<Self> {
        let p: EchoParams = serde_path_to_error::deserialize(params)
            .map_err(|e| anyhow::anyhow!("[modules.echo] {}: {}", e.path(), e.inner()))?;
        p.canceller()?;
        Ok(p)
    }

    fn canceller(&self) -> anyhow::Result<Canceller> {
        Canceller::new(CancellerConfig {
            lead_ms: self.lead_ms,
            jitter_ms: self.jitter_ms,
            residual_gate: self.residual_gate,
            hold_ms: self.hold_ms,
        })
        .map_err(|e| anyhow::anyhow!("[modules.echo] {e}"))
    }
}

impl Module for EchoModule {
    fn name(&self) -> &'static str {
        "echo"
    }

    fn check(&self, params: &serde_json::Value) -> anyhow::Result<()> {
        EchoParams::from_json(params).map(drop)
    }

    fn run(self: Box<Self>, ctx: ModuleContext) -> ModuleFuture {
        Box::pin(async move {
            let params = EchoParams::from_json(&ctx.params)?;
            let client = ctx.client.clone();
            let mut stop = ctx.stopping();
            let Some(publisher) = on_demand::output(
                &client,
                channels::AUDIO_CLEAN.name,
                channels::headers::AUDIO_CLEAN,
                &mut stop,
            )
            .await
            else {
                return Ok(());
            };
            let mut listening = publisher.subscribers();
            let mut report = Report::default();
            loop {
                if !on_demand::until_listened(&mut listening, &mut stop).await {
                    return Ok(());
                }
                let microphone = client.subscribe(channels::AUDIO.name).await?;
                let speech = client.subscribe(channels::SPEECH.name).await?;
                let avatar = client.subscribe(channels::AVATAR.name).await?;
                let playback = client.subscribe(channels::PLAYBACK.name).await?;
                // A fresh canceller per listening period: the room and the delay may have changed meanwhile.
                let mut canceller = params.canceller()?;
                let mut cleaned = Vec::new();
                loop {
                    tokio::select! {
                        biased;
                        () = stop.stopped() => return Ok(()),
                        _ = on_demand::unlistened(&mut listening) => break,
                        d = speech.recv() => {
                            let Some(d) = d else { return Ok(()) };
                            let framed = speech.info().is_some_and(|info| info.header.contains("\"framing\""));
                            match (framed, d.payload.get(..8)) {
                                (true, Some(head)) => {
                                    let word = |i: usize| u32::from_le_bytes([head[i], head[i + 1], head[i + 2], head[i + 3]]);
                                    canceller.speech(d.ts_us, Some((word(0), word(4))), &d.payload[8..]);
                                }
                                _ => canceller.speech(d.ts_us, None, &d.payload),
                            }
                        }
                        d = avatar.recv() => {
                            let Some(d) = d else { return Ok(()) };
                            if let Ok(AvatarCommand::SpeechStop { utterance, .. }) = serde_json::from_slice(&d.payload) {
                                canceller.stopped(d.ts_us, utterance.and_then(|u| u32::try_from(u).ok()));
                            }
                        }
                        d = playback.recv() => {
                            let Some(d) = d else { return Ok(()) };
                            if let Ok(p) = serde_json::from_slice::<PlaybackStarted>(&d.payload)
                                && let Ok(utterance) = u32::try_from(p.utterance)
                            {
                                canceller.played(utterance, (p.at_ms.max(0.0) * 1000.0) as u64);
                            }
                        }
                        d = microphone.recv() => {
                            let Some(d) = d else { return Ok(()) };
                            cleaned.clear();
                            let restarted = canceller.microphone(d.seq, d.ts_us, &d.payload, &mut cleaned);
                            // Awaited, not tried: the satellites must hear every sample. A full link stalls only
                            // this module; the hub drops its oldest microphone messages for it (counted).
                            let split = restarted.unwrap_or(0);
                            if split > 0 {
                                publisher.publish(bytes::Bytes::copy_from_slice(&cleaned[..split])).await?;
                            }
                            if restarted.is_some() {
                                // The contract's stream break: what follows is a new stream.
                                publisher.publish(bytes::Bytes::new()).await?;
                            }
                            if cleaned.len() > split {
                                publisher.publish(bytes::Bytes::copy_from_slice(&cleaned[split..])).await?;
                            }
                            report.maybe(&ctx, &canceller);
                        }
                    }
                }
                report.now(&ctx, &canceller);
            }
        })
    }
}

/// `/api/status` figures, at most once a second while audio flows (no timer: idle costs nothing).
#[derive(Debug, Default)]
struct Report {
    last: Option<Instant>,
}

impl Report {
    fn maybe(&mut self, ctx: &ModuleContext, canceller: &Canceller) {
        if self
            .last
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(1))
        {
            self.now(ctx, canceller);
        }
    }

    fn now(&mut self, ctx: &ModuleContext, canceller: &Canceller) {
        self.last = Some(Instant::now());
        let s = canceller.stats();
        ctx.report(serde_json::json!({
            "frames": s.frames,
            "frames_with_speech": s.frames_with_speech,
            "frames_cancelled": s.frames_cancelled,
            "frames_silenced": s.frames_silenced,
            "frames_held": s.frames_held,
            "echo_found_after_ms": s.echo_found_after_ms,
            "residue_gain_db": s.residue_gain_db,
            "restarts": s.restarts,
            "erle_db": s.erle_db,
            "delay_ms": s.delay_ms,
        }));
    }
}
