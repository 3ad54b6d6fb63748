//! The observer: one hub client subscribed to `Agent.transcript`, `Agent.rules`, `Agent.chat.reply` and
//! `Agent.speech`, stamping each message with the wall time it arrived, and the measurement of a single hub hop.

use agent_contract::channels as ch;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use bytes::Bytes;
use flow::{Client, Subscription};
use serde_json::Value;

use crate::answer::Answer;
use crate::chat_report::ChatRunFigures;
use crate::report::{Decode, RunFigures};
use crate::speech_clip::Ending;

/// Subscriptions to what the agent says about an utterance.
pub struct Watcher {
    transcript: Subscription,
    rules: Subscription,
    /// The language model's events (`prompt`, `sentence`, `end`), for the chat phase.
    reply: Subscription,
    speech: Subscription,
    /// Speech still arriving from the previous reply is not this run's.
    last_speech: Option<Instant>,
}

enum Seen {
    Transcript(Value),
    Rules(Value),
    Reply(Value),
    Speech,
}

impl Watcher {
    pub async fn start(client: &Client) -> anyhow::Result<Watcher> {
        Ok(Watcher {
            transcript: client.subscribe(ch::TRANSCRIPT.name).await?,
            rules: client.subscribe(ch::RULES.name).await?,
            reply: client.subscribe(ch::CHAT_REPLY.name).await?,
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
                d = self.reply.recv() => json(&d.context("Agent.chat.reply ended")?.payload).map(Seen::Reply),
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
        let mut hearing = Hearing::new(end_of_speech);
        loop {
            let Ok(next) = tokio::time::timeout_at(deadline.into(), self.next()).await else {
                bail!("no reply in time; {}", hearing.so_far());
            };
            let (at, seen) = next?;
            if matches!(seen, Seen::Speech)
                && let Some(figures) = hearing.figures(at)
            {
                return Ok(figures);
            }
            hearing.take(at, seen);
        }
    }

    /// Follows one utterance answered by the language model, as [`Watcher::follow`] does, and the model's turn on
    /// `Agent.chat.reply`: its `prompt` event, its first `sentence`, the first reply PCM after that sentence, and
    /// its `end` (returned once the turn has ended, so the next question does not overlap it).
    pub async fn follow_chat(
        &mut self,
        end_of_speech: Instant,
        deadline: Instant,
    ) -> anyhow::Result<ChatRunFigures> {
        let mut hearing = Hearing::new(end_of_speech);
        // The prompts seen since the end of speech, by turn: the turn of the first sentence picks its own.
        let mut prompts: Vec<(Value, Instant)> = Vec::new();
        let mut first_sentence: Option<(Value, Instant, String)> = None;
        let mut base: Option<RunFigures> = None;
        let mut ended: Option<(Instant, Value)> = None;
        // Speculative turns started at a pause and dropped: their tokens are wasted work.
        let mut dropped: Vec<u64> = Vec::new();
        // The knowledge folder's passages quoted in the facts (the trace's `passage` steps).
        let mut passages: Vec<String> = Vec::new();
        loop {
            let Ok(next) = tokio::time::timeout_at(deadline.into(), self.next()).await else {
                bail!(
                    "no spoken reply from the model in time; {}, prompt events: {}, first sentence: {:?}, first PCM: {}, end: {}",
                    hearing.so_far(),
                    prompts.len(),
                    first_sentence.map(|s| s.2),
                    base.is_some(),
                    ended.is_some()
                );
            };
            let (at, seen) = next?;
            match seen {
                Seen::Reply(v) => match v["event"].as_str() {
                    Some("prompt") => prompts.push((v["turn"].clone(), at)),
                    Some("sentence")
                        if first_sentence.is_none()
                            && v["index"] == 0
                            && prompts.iter().any(|(turn, _)| *turn == v["turn"]) =>
                    {
                        let text = v["text"].as_str().unwrap_or_default().to_owned();
                        first_sentence = Some((v["turn"].clone(), at, text));
                    }
                    // A dropped speculative turn published nothing but its end.
                    Some("end") if v["stats"]["dropped"] == true => {
                        dropped.push(v["stats"]["tokens"].as_u64().unwrap_or(0));
                    }
                    Some("end") if prompts.iter().any(|(turn, _)| *turn == v["turn"]) => {
                        match &first_sentence {
                            None => bail!(
                                "the model's turn ended without a sentence: {v}; {}",
                                hearing.so_far()
                            ),
                            Some((turn, _, _)) if v["turn"] == *turn => {
                                ended = Some((at, v["stats"].clone()));
                            }
                            Some(_) => {}
                        }
                    }
                    _ => {}
                },
                Seen::Speech => {
                    if base.is_none()
                        && let Some((_, sentence_at, _)) = &first_sentence
                        && at >= *sentence_at
                    {
                        base = hearing.figures(at);
                    }
                }
                other => {
                    if let Seen::Rules(v) = &other
                        && v["chat"]["step"] == "passage"
                    {
                        let text = v["chat"]["text"].as_str().unwrap_or_default();
                        passages.push(text.split(':').next().unwrap_or_default().to_owned());
                    }
                    hearing.take(at, other)
                }
            }
            // The spoken reply's first PCM and the turn's end may come in either order (one sentence ends the turn
            // at once).
            if let (Some(base), Some((sentence_turn, sentence_at, text)), Some((end, stats))) =
                (&base, &first_sentence, &ended)
            {
                let prompt = prompts
                    .iter()
                    .find(|(turn, _)| turn == sentence_turn)
                    .map_or(*sentence_at, |(_, at)| *at);
                return Ok(ChatRunFigures::new(
                    base.clone(),
                    prompt,
                    *sentence_at,
                    *end,
                    stats,
                    text.clone(),
                    dropped,
                )
                .with_passages(passages));
            }
        }
    }

    /// Follows one question typed as a final transcript: the rule trace that heard it, the `passage` steps that
    /// follow, and what was said: the recalled passage, the model's sentences up to its turn's end, or the rule's
    /// own actions. Gives up at `deadline`.
    pub async fn follow_answer(
        &mut self,
        question: &str,
        deadline: Instant,
    ) -> anyhow::Result<Answer> {
        let mut answer = Answer::default();
        let mut turn: Option<Value> = None;
        let mut sentences: Vec<String> = Vec::new();
        loop {
            let Ok(next) = tokio::time::timeout_at(deadline.into(), self.next()).await else {
                bail!(
                    "no whole answer in time; action {:?}, passages {}, sentences {:?}",
                    answer.action,
                    answer.passages.len(),
                    sentences
                );
            };
            match next?.1 {
                Seen::Rules(v) if v["chat"]["step"] == "passage" && !answer.action.is_empty() => {
                    let text = v["chat"]["text"].as_str().unwrap_or_default().to_owned();
                    answer.passages.push(text);
                }
                // A chat step's trace is not a rule's.
                Seen::Rules(v)
                    if v["chat"].is_null() && answer.action.is_empty() && heard(&v, question) =>
                {
                    answer.action = v["action"].as_str().unwrap_or_default().to_owned();
                }
                Seen::Reply(v) if answer.by_model() => match v["event"].as_str() {
                    Some("prompt") if turn.is_none() => turn = Some(v["turn"].clone()),
                    Some("sentence") if turn.as_ref() == Some(&v["turn"]) => {
                        sentences.push(v["text"].as_str().unwrap_or_default().to_owned());
                    }
                    Some("end") if turn.as_ref() == Some(&v["turn"]) => {
                        answer.spoken = sentences.join(" ");
                        return Ok(answer);
                    }
                    _ => {}
                },
                _ => {}
            }
            if answer.recalled()
                && let Some(passage) = answer.passages.first()
            {
                // `file (heading): text`: what was said is the text.
                answer.spoken = passage
                    .split_once("): ")
                    .map_or(passage.as_str(), |(_, text)| text)
                    .to_owned();
                return Ok(answer);
            }
            if !answer.action.is_empty() && !answer.recalled() && !answer.by_model() {
                answer.spoken = answer.action.clone();
                return Ok(answer);
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

/// How far one utterance has got on the hub: its `vad` end, its transcript and the rule trace that heard it.
struct Hearing {
    end_of_speech: Instant,
    vad_end: Option<(Instant, String, u64)>,
    transcript: Option<(Instant, String, u64, Decode)>,
    rules: Option<Instant>,
    /// The rule changes seen after the transcript, to say why a run found none of its own.
    other_rules: Vec<String>,
}

impl Hearing {
    fn new(end_of_speech: Instant) -> Hearing {
        Hearing {
            end_of_speech,
            vad_end: None,
            transcript: None,
            rules: None,
            other_rules: Vec::new(),
        }
    }

    /// Takes in one transcript message or rule trace that arrived at `at`.
    fn take(&mut self, at: Instant, seen: Seen) {
        match seen {
            Seen::Transcript(v) if v["vad"] == "end" && self.vad_end.is_none() => {
                // An end announced before our end of speech belongs to a pause inside the clip.
                if at >= self.end_of_speech
                    && let Some(id) = v["utterance"].as_str()
                {
                    self.vad_end = Some((at, id.to_owned(), v["at_ms"].as_u64().unwrap_or(0)));
                }
            }
            Seen::Transcript(v) => {
                if let Some((_, id, _)) = &self.vad_end
                    && v["utterance"].as_str() == Some(id.as_str())
                    && let Some(text) = v["text"].as_str()
                {
                    self.transcript = Some((
                        at,
                        text.trim().to_owned(),
                        v["processing_ms"].as_u64().unwrap_or(0),
                        Decode {
                            speculative: v["speculative"].as_bool().unwrap_or(false),
                            full_window_retry: v["full_window_retry"].as_bool().unwrap_or(false),
                            turn: v["turn"].as_str().map(str::to_owned),
                        },
                    ));
                }
            }
            Seen::Rules(v) => {
                if let Some((_, text, _, _)) = &self.transcript
                    && self.rules.is_none()
                {
                    if heard(&v, text) {
                        self.rules = Some(at);
                    } else {
                        self.other_rules
                            .push(format!("{} because {}", v["rule"], v["because"]));
                    }
                }
            }
            Seen::Reply(_) | Seen::Speech => {}
        }
    }

    /// The run's figures with its first reply PCM at `first_pcm`, once everything before it has been seen.
    fn figures(&self, first_pcm: Instant) -> Option<RunFigures> {
        let (Some(rules), Some((t_at, text, processing_ms, decode)), Some((v_at, _, vad_ms))) =
            (self.rules, &self.transcript, &self.vad_end)
        else {
            return None;
        };
        (first_pcm >= rules).then(|| RunFigures {
            end_of_speech: self.end_of_speech,
            vad_end: *v_at,
            transcript: *t_at,
            rules,
            first_pcm,
            processing_ms: *processing_ms,
            decode: decode.clone(),
            vad_end_vs_ours_ms: *vad_ms as f64 - wall_ms(self.end_of_speech),
            text: text.clone(),
            ending: Ending::Turn,
        })
    }

    /// How far the utterance got, for a run given up.
    fn so_far(&self) -> String {
        format!(
            "vad end: {:?}, transcript: {:?}, rule change: {}, other rule changes: {:?}",
            self.vad_end.as_ref().map(|v| &v.1),
            self.transcript.as_ref().map(|t| &t.1),
            self.rules.is_some(),
            self.other_rules
        )
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
