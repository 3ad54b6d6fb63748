//! Barge-in: the agent is made to speak a long reply, and the microphone stand-in talks over it. Measured from
//! the publication of the chunk holding the user's first voiced sample (the onset) to the arrival of the
//! `speech_stop` the TTS module sends the page; a 150 ms burst of voice said over the reply must stop nothing.

use agent_contract::channels as ch;
use std::time::{Duration, Instant};

use anyhow::Context;
use flow::{Client, Subscription};
use serde_json::Value;
use tokio::sync::{mpsc, oneshot};

use crate::speech_clip::{Clip, Say};

/// What the agent is asked to say: long enough to talk over.
const LONG_REPLY: &str = "Let me tell you about the weather today. In the morning it will be cloudy with a \
    chance of light rain, clearing towards noon, and the afternoon should be sunny and warm.";
/// How long the agent speaks before the user talks over it.
const SPEAKING_BEFORE: Duration = Duration::from_millis(600);
/// A stop later than this after the onset is not the barge-in (the reply would have ended by itself).
const STOP_PATIENCE: Duration = Duration::from_secs(5);
/// How long a burst of voice is given to (wrongly) stop the agent.
const BURST_WINDOW: Duration = Duration::from_millis(1500);

/// The figures of the barge-in runs.
#[derive(Debug, Default)]
pub struct BargeIns {
    /// Onset published -> `speech_stop` received, ms.
    pub onset_to_stop: Vec<f64>,
    /// Onset published -> the `vad` start received, ms.
    pub onset_to_vad_start: Vec<f64>,
    /// Runs where the user talked over the reply and nothing stopped it.
    pub missed: usize,
    /// Bursts of voice said over the reply, and how many of them stopped it.
    pub bursts: usize,
    pub burst_stops: usize,
}

/// The observer's side: the channels a barge-in shows on.
pub struct Rig<'a> {
    pub client: &'a Client,
    pub say: &'a mpsc::Sender<Say>,
    avatar: Subscription,
    transcript: Subscription,
    speech: Subscription,
}

impl<'a> Rig<'a> {
    pub async fn start(client: &'a Client, say: &'a mpsc::Sender<Say>) -> anyhow::Result<Rig<'a>> {
        Ok(Rig {
            client,
            say,
            avatar: client.subscribe(ch::AVATAR.name).await?,
            transcript: client.subscribe(ch::TRANSCRIPT.name).await?,
            speech: client.subscribe(ch::SPEECH.name).await?,
        })
    }

    /// Starts the long reply and waits until it has been playing for a while.
    async fn agent_speaking(&self) -> anyhow::Result<()> {
        while self.speech.try_recv().is_some() {}
        let body = serde_json::json!({ "text": LONG_REPLY }).to_string();
        self.client
            .call(ch::SAY.name, body.into_bytes(), Duration::from_secs(5))
            .await
            .context("asking the TTS module to speak")?;
        tokio::time::timeout(Duration::from_secs(10), self.speech.recv())
            .await
            .context("the reply never started")?
            .context("Agent.speech ended")?;
        tokio::time::sleep(SPEAKING_BEFORE).await;
        while self.avatar.try_recv().is_some() {}
        while self.transcript.try_recv().is_some() {}
        Ok(())
    }

    /// Says `clip` over the reply and waits for the stop; returns (onset -> stop, onset -> vad start) in ms, or
    /// `None` when nothing stopped the reply.
    pub async fn talk_over(&self, clip: &Clip) -> anyhow::Result<Option<(f64, Option<f64>)>> {
        self.agent_speaking().await?;
        let (spoken, _) = oneshot::channel();
        let (onset_tx, onset_rx) = oneshot::channel();
        self.say
            .send(Say {
                clip: clip.clone(),
                spoken,
                onset: Some(onset_tx),
            })
            .await
            .context("the microphone stopped")?;
        let onset = onset_rx.await.context("the microphone stopped")?;
        let mut vad_start = None;
        let stop = tokio::time::timeout(STOP_PATIENCE, async {
            loop {
                tokio::select! {
                    d = self.avatar.recv() => {
                        let d = d.context("Agent.avatar ended")?;
                        if is_barge_in(&d.payload) {
                            return anyhow::Ok(Instant::now());
                        }
                    }
                    d = self.transcript.recv() => {
                        let d = d.context("Agent.transcript ended")?;
                        if vad_start.is_none()
                            && serde_json::from_slice::<Value>(&d.payload).is_ok_and(|v| v["vad"] == "start")
                        {
                            vad_start = Some(Instant::now());
                        }
                    }
                }
            }
        })
        .await;
        self.until_quiet().await;
        let ms = |at: Instant| at.saturating_duration_since(onset).as_secs_f64() * 1000.0;
        match stop {
            Ok(stopped) => Ok(Some((ms(stopped?), vad_start.map(ms)))),
            Err(_) => Ok(None),
        }
    }

    /// Says `burst` over the reply; true when it stopped the reply.
    pub async fn burst_over(&self, burst: &Clip) -> anyhow::Result<bool> {
        self.agent_speaking().await?;
        let (spoken, said) = oneshot::channel();
        self.say
            .send(Say {
                clip: burst.clone(),
                spoken,
                onset: None,
            })
            .await
            .context("the microphone stopped")?;
        said.await.context("the microphone stopped")?;
        let stopped = tokio::time::timeout(BURST_WINDOW, async {
            loop {
                match self.avatar.recv().await {
                    Some(d) if is_barge_in(&d.payload) => return true,
                    Some(_) => {}
                    None => return false,
                }
            }
        })
        .await
        .unwrap_or(false);
        // Stop the reply either way, so the next run starts from quiet.
        let body = serde_json::json!({ "cancel": "all" }).to_string();
        self.client
            .call(ch::SAY.name, body.into_bytes(), Duration::from_secs(5))
            .await?;
        self.until_quiet().await;
        Ok(stopped)
    }

    /// Waits until no speech has arrived for a second (the user's words are answered too, and that answer must
    /// not run into the next run).
    async fn until_quiet(&self) {
        while tokio::time::timeout(Duration::from_secs(1), self.speech.recv())
            .await
            .is_ok_and(|d| d.is_some())
        {}
    }
}

fn is_barge_in(payload: &[u8]) -> bool {
    serde_json::from_slice::<Value>(payload)
        .is_ok_and(|v| v["cmd"] == "speech_stop" && v["barge_in"] == true)
}

/// Runs `runs` talk-overs (cycling through `clips`) and as many bursts.
pub async fn measure(
    rig: &Rig<'_>,
    clips: &[&Clip],
    burst: &Clip,
    runs: usize,
) -> anyhow::Result<BargeIns> {
    let mut out = BargeIns::default();
    for run in 0..runs {
        let clip = clips[run % clips.len()];
        match rig.talk_over(clip).await? {
            Some((stop, vad)) => {
                println!(
                    "  barge-in {:>2} {:<12} onset -> speech_stop {stop:>6.1} ms (vad start {})",
                    run + 1,
                    clip.name,
                    vad.map_or_else(|| "not seen".to_owned(), |v| format!("{v:.1} ms"))
                );
                out.onset_to_stop.push(stop);
                if let Some(v) = vad {
                    out.onset_to_vad_start.push(v);
                }
            }
            None => {
                println!(
                    "  barge-in {:>2} {:<12} missed: the reply went on",
                    run + 1,
                    clip.name
                );
                out.missed += 1;
            }
        }
        out.bursts += 1;
        let stopped = rig.burst_over(burst).await?;
        println!(
            "  burst    {:>2} {:.0} ms of voice: {}",
            run + 1,
            burst.seconds() * 1000.0,
            if stopped {
                "STOPPED the reply"
            } else {
                "ignored"
            }
        );
        out.burst_stops += usize::from(stopped);
    }
    Ok(out)
}
