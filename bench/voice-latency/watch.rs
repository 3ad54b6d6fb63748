//! The observer: one hub client subscribed to `Agent.transcript`, `Agent.rules` and `Agent.speech`, stamping each
//! message with the wall time it arrived, and the measurement of a single hub hop.

use agent_contract::channels as ch;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use bytes::Bytes;
use flow::{Client, Subscription};
use serde_json::Value;

use crate::report::{Decode, RunFigures};
use crate::speech_clip::Ending;

/// Subscriptions to what the agent says about an utterance.
pub struct Watcher {
    transcript: Subscription,
    rules: Subscription,
    speech: Subscription,
    /// Speech still arriving from the previous reply is not this run's.
    last_speech: Option<Instant>,
}

enum Seen {
    Transcript(Value),
    Rules(Value),
    Speech,
}

impl Watcher {
    pub async fn start(client: &Client) -> anyhow::Result<Watcher> {
        Ok(Watcher {
            transcript: client.subscribe(ch::TRANSCRIPT.name).await?,
            rules: client.subscribe(ch::RULES.name).await?,
            speech: client.subscribe(ch::SPEECH.name).await?,
            last_speech: None,
        })
    }

    async fn next(&mut self) -> anyhow::Result<(Instant, Seen)> {
        let json = |p: &Bytes| serde_json::from_slice::<Value>(p).ok();
        loop {
            // Biased in causal order: the hub sends a transcript before the rule trace it causes and the trace
            // before the speech that follows, and the client files them in that order into separate queues; polling
            // fairly could take a trace before its transcript and miss the match.
            let seen = tokio::select! {
                biased;
                d = self.transcript.recv() => json(&d.context("Agent.transcript ended")?.payload).map(Seen::Transcript),
                d = self.rules.recv() => json(&d.context("Agent.rules ended")?.payload).map(Seen::Rules),
                d = self.speech.recv() => d.context("Agent.speech ended").map(|_| Some(Seen::Speech))?,
            };
            let now = Instant::now();
            if let Some(seen) = seen {
                if matches!(seen, Seen::Speech) {
                    self.last_speech = Some(now);
                }
                return Ok((now, seen));
            }
        }
    }

    /// Follows one utterance whose speech ended (was published) at `end_of_speech`: its `vad` end, its transcript
    /// (named by the end event), the rule trace that heard its text, and the first reply PCM after that trace.
    /// Gives up at `deadline`, saying how far the utterance got.
    pub async fn follow(
        &mut self,
        end_of_speech: Instant,
        deadline: Instant,
    ) -> anyhow::Result<RunFigures> {
        let mut vad_end: Option<(Instant, String, u64)> = None;
        let mut transcript: Option<(Instant, String, u64, Decode)> = None;
        let mut rules: Option<Instant> = None;
        // The rule changes seen after the transcript, to say why a run found none of its own.
        let mut other_rules: Vec<String> = Vec::new();
        loop {
            let Ok(next) = tokio::time::timeout_at(deadline.into(), self.next()).await else {
                bail!(
                    "no reply in time; vad end: {:?}, transcript: {:?}, rule change: {}, other rule changes: {:?}",
                    vad_end.map(|v| v.1),
                    transcript.map(|t| t.1),
                    rules.is_some(),
                    other_rules
                );
            };
            let (at, seen) = next?;
            match seen {
                Seen::Transcript(v) if v["vad"] == "end" && vad_end.is_none() => {
                    // An end announced before our end of speech belongs to a pause inside the clip.
                    if at >= end_of_speech
                        && let Some(id) = v["utterance"].as_str()
                    {
                        vad_end = Some((at, id.to_owned(), v["at_ms"].as_u64().unwrap_or(0)));
                    }
                }
                Seen::Transcript(v) => {
                    if let Some((_, id, _)) = &vad_end
                        && v["utterance"].as_str() == Some(id.as_str())
                        && let Some(text) = v["text"].as_str()
                    {
                        transcript = Some((
                            at,
                            text.trim().to_owned(),
                            v["processing_ms"].as_u64().unwrap_or(0),
                            Decode {
                                speculative: v["speculative"].as_bool().unwrap_or(false),
                                full_window_retry: v["full_window_retry"]
                                    .as_bool()
                                    .unwrap_or(false),
                                turn: v["turn"].as_str().map(str::to_owned),
                            },
                        ));
                    }
                }
                Seen::Rules(v) => {
                    if let Some((_, text, _, _)) = &transcript
                        && rules.is_none()
                    {
                        if heard(&v, text) {
                            rules = Some(at);
                        } else {
                            other_rules.push(format!("{} because {}", v["rule"], v["because"]));
                        }
                    }
                }
                Seen::Speech => {
                    if let (
                        Some(rules),
                        Some((t_at, text, processing_ms, decode)),
                        Some((v_at, _, vad_ms)),
                    ) = (rules, &transcript, &vad_end)
                        && at >= rules
                    {
                        return Ok(RunFigures {
                            end_of_speech,
                            vad_end: *v_at,
                            transcript: *t_at,
                            rules,
                            first_pcm: at,
                            processing_ms: *processing_ms,
                            decode: decode.clone(),
                            vad_end_vs_ours_ms: *vad_ms as f64 - wall_ms(end_of_speech),
                            text: text.clone(),
                            ending: Ending::Turn,
                        });
                    }
                }
            }
        }
    }

    /// Waits until no reply speech has arrived for `quiet` (the agent has finished talking).
    pub async fn until_quiet(&mut self, quiet: Duration) -> anyhow::Result<()> {
        loop {
            let since = self.last_speech.map_or(quiet, |t| t.elapsed());
            if since >= quiet {
                return Ok(());
            }
            // Anything arriving meanwhile is the tail of this run; only its time matters.
            let _ = tokio::time::timeout(quiet - since, self.next()).await;
        }
    }
}

/// Whether a rule trace was caused by hearing `text` (one of its `because` facts is `heard("text")`).
fn heard(trace: &Value, text: &str) -> bool {
    trace["because"].as_array().is_some_and(|facts| {
        facts.iter().any(|f| {
            f.as_str()
                .is_some_and(|f| f.starts_with("heard(") && f.contains(text))
        })
    })
}

/// Wall clock of an `Instant`, in ms since the Unix epoch (the hub's clock on this machine).
fn wall_ms(at: Instant) -> f64 {
    let now_wall = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64() * 1000.0);
    now_wall - at.elapsed().as_secs_f64() * 1000.0
}

/// The cost of one hub hop on this machine: a 20 ms audio-sized message published by one TCP client and received by
/// another, `samples` times at 20 ms spacing; milliseconds.
pub async fn hub_hop(from: &Client, to: &Client, samples: usize) -> anyhow::Result<Vec<f64>> {
    let publisher = from
        .publisher("Bench.hop", r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let sub = to.subscribe("Bench.hop").await?;
    let mut subscribed = publisher.subscribers();
    tokio::time::timeout(Duration::from_secs(10), subscribed.wait_for(|on| *on))
        .await
        .context("the hop subscriber did not arrive")??;
    let payload = Bytes::from(vec![0u8; 882]);
    let mut out = Vec::with_capacity(samples);
    for _ in 0..samples {
        let sent = Instant::now();
        publisher.publish(payload.clone()).await?;
        tokio::time::timeout(Duration::from_secs(5), sub.recv())
            .await
            .context("a hop message was lost")?
            .context("the hop subscription ended")?;
        out.push(sent.elapsed().as_secs_f64() * 1000.0);
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    Ok(out)
}

/// Waits until a channel exists.
pub async fn wait_channel(client: &Client, name: &str, patience: Duration) -> anyhow::Result<()> {
    let deadline = tokio::time::Instant::now() + patience;
    let mut events = client.events();
    loop {
        if client.channels().await?.iter().any(|c| c.name == name) {
            return Ok(());
        }
        tokio::select! {
            _ = events.recv() => {}
            () = tokio::time::sleep_until(deadline) => bail!("channel {name} did not appear in {patience:?}"),
        }
    }
}
