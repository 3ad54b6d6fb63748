//! The `observer` module: the agent's figures at `/metrics`, read off the contract channels like any other
//! consumer reads them: vision stage times from `Agent.detections`, ASR per satellite from `Agent.transcript` and
//! the claim channels, and the stages of each conversational turn from the VAD events, transcripts, rule trace and
//! speech ([`turns`]), which it also publishes turn by turn on `Agent.latency` for the page's status strip, and
//! records as the turn's spans when telemetry is on ([`spans`]). It reads and reports only, so switching it off
//! changes nothing else.

mod claims;
mod pace;
mod spans;
mod turns;

use agent_contract::channels;
use agent_contract::chat::ChatEvent;
use agent_contract::detections::DetectionsMsg;
use agent_contract::latency::TurnLatency;
use agent_contract::rules::RuleChange;
use agent_contract::say::PlaybackStarted;
use agent_contract::transcript::{TranscriptMessage, VadKind, VadMessage};
use flow::{ClientEvent, Data};
use flow_hub::metrics::{HistogramFamily, Metrics, latency_family};
use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use serde::Deserialize;
use tokio::sync::broadcast::error::RecvError;

use claims::{ClaimNews, Claims};
use flow_hub::module::{Module, ModuleContext, ModuleFuture};
use pace::{Budgets, Pace};
use tracing::{info, warn};
use turns::{Stage, TurnDone, Turns};

/// The `observer` module.
#[derive(Debug, Default)]
pub struct ObserverModule;

/// `[modules.observer]`: the switch and the turn's stage budgets (`pace.rs`).
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct ObserverParams {
    enabled: bool,
    budgets_ms: Budgets,
}

impl Default for ObserverParams {
    fn default() -> Self {
        ObserverParams {
            enabled: true,
            budgets_ms: Budgets::default(),
        }
    }
}

fn observer_params(params: &serde_json::Value) -> anyhow::Result<ObserverParams> {
    let p = serde_path_to_error::deserialize::<_, ObserverParams>(params)
        .map_err(|e| anyhow::anyhow!("[modules.observer] {}: {}", e.path(), e.inner()))?;
    p.budgets_ms
        .validate()
        .map_err(|e| anyhow::anyhow!("[modules.observer] {e}"))?;
    Ok(p)
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StageLabel {
    stage: &'static str,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct SatelliteLabel {
    satellite: String,
}

/// The families this module keeps up to date.
#[derive(Debug, Clone)]
struct Figures {
    vision: HistogramFamily<StageLabel>,
    asr_utterances: Family<SatelliteLabel, Counter>,
    asr_processing: HistogramFamily<SatelliteLabel>,
    asr_claims: Family<SatelliteLabel, Counter>,
    asr_claims_lost: Family<SatelliteLabel, Counter>,
    asr_claims_retried: Family<SatelliteLabel, Counter>,
    conversation: HistogramFamily<StageLabel>,
    behind: Family<StageLabel, Gauge>,
    preemptive: Family<OutcomeLabel, Counter>,
    preemptive_wasted: Counter,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct OutcomeLabel {
    outcome: &'static str,
}

impl Figures {
    fn register(metrics: &Metrics) -> Self {
        let f = Figures {
            vision: latency_family(),
            asr_utterances: Family::default(),
            asr_processing: latency_family(),
            asr_claims: Family::default(),
            asr_claims_lost: Family::default(),
            asr_claims_retried: Family::default(),
            conversation: latency_family(),
            behind: Family::default(),
            preemptive: Family::default(),
            preemptive_wasted: Counter::default(),
        };
        metrics.register(
            "agent_chat_preemptive",
            "Replies the model started on the transcript of a pause, by outcome: kept (the final transcript adopted \
             it) or cancelled (it did not)",
            f.preemptive.clone(),
        );
        metrics.register(
            "agent_chat_preemptive_wasted_tokens",
            "Tokens generated for speculative replies nobody adopted",
            f.preemptive_wasted.clone(),
        );
        metrics.register(
            "agent_turn_stage_behind",
            "1 while a stage of the turn (vad, transcription, rule, reply) is behind on this machine: its median over \
             the last turns is over its budget (docs/metrics.md)",
            f.behind.clone(),
        );
        metrics.register(
            "agent_vision_stage_seconds",
            "Time the vision module spent per frame, by stage (decode, faces, motion, codes, total)",
            f.vision.clone(),
        );
        metrics.register(
            "agent_asr_utterances",
            "Final transcripts by the satellite that made them",
            f.asr_utterances.clone(),
        );
        metrics.register(
            "agent_asr_processing_seconds",
            "Transcription time of each final transcript, by satellite",
            f.asr_processing.clone(),
        );
        metrics.register(
            "agent_asr_claims",
            "Utterances claimed, by satellite",
            f.asr_claims.clone(),
        );
        metrics.register(
            "agent_asr_claims_lost",
            "Claims whose holder vanished before it was done, by satellite",
            f.asr_claims_lost.clone(),
        );
        metrics.register(
            "agent_asr_claims_retried",
            "Utterances claimed again after a lost claim, by the satellite that retried",
            f.asr_claims_retried.clone(),
        );
        metrics.register(
            "agent_conversation_seconds",
            "Stages of a conversational turn: speech_end_to_vad_end, vad_end_to_transcript, transcript_to_rule, \
             rule_to_reply_audio and the whole speech_end_to_reply_audio",
            f.conversation.clone(),
        );
        f
    }

    fn stages(&self, done: Vec<(Stage, u64)>) {
        for (stage, us) in done {
            self.conversation
                .get_or_create(&StageLabel {
                    stage: stage.label(),
                })
                .observe(us as f64 / 1e6);
        }
    }

    /// The two stages a reply completes (the earlier ones were observed as they happened).
    fn reply(&self, turn: &TurnDone) {
        self.stages(vec![
            (Stage::RuleToReplyAudio, turn.reply_us),
            (Stage::SpeechEndToReplyAudio, turn.total_us),
        ]);
    }

    /// The end of a chat turn: a speculative one was kept or wasted.
    fn chat_end(&self, data: &Data) {
        let Ok(ChatEvent::End { stats, .. }) = serde_json::from_slice::<ChatEvent>(&data.payload)
        else {
            return;
        };
        if !stats.speculated {
            return;
        }
        let outcome = if stats.dropped { "cancelled" } else { "kept" };
        self.preemptive
            .get_or_create(&OutcomeLabel { outcome })
            .inc();
        if stats.dropped {
            self.preemptive_wasted.inc_by(u64::from(stats.tokens));
        }
    }

    fn detections(&self, data: &Data) {
        let Ok(d) = serde_json::from_slice::<DetectionsMsg>(&data.payload) else {
            return;
        };
        let Some(t) = d.timing else { return };
        let stages = [
            ("decode", Some(t.decode_ms)),
            ("faces", t.faces_ms),
            ("motion", t.motion_ms),
            ("codes", t.codes_ms),
            ("total", Some(t.total_ms)),
        ];
        for (stage, ms) in stages {
            if let Some(ms) = ms {
                self.vision
                    .get_or_create(&StageLabel { stage })
                    .observe(ms / 1000.0);
            }
        }
    }

    fn claim(&self, news: ClaimNews) {
        match news {
            ClaimNews::Taken { satellite, retry } => {
                let label = SatelliteLabel { satellite };
                self.asr_claims.get_or_create(&label).inc();
                if retry {
                    self.asr_claims_retried.get_or_create(&label).inc();
                }
            }
            ClaimNews::Lost { satellite } => {
                self.asr_claims_lost
                    .get_or_create(&SatelliteLabel { satellite })
                    .inc();
            }
        }
    }
}

/// What one `Agent.transcript` message is, read strictly through the contract's types.
enum Heard {
    VadEnd { utterance: String, at_ms: u64 },
    Final(TranscriptMessage),
    Other,
}

fn heard(payload: &[u8]) -> Heard {
    let Ok(value) = serde_json::from_slice::<serde_json::Value>(payload) else {
        return Heard::Other;
    };
    if value.get("vad").is_some() {
        return match serde_json::from_value::<VadMessage>(value) {
            Ok(VadMessage {
                vad: VadKind::End,
                at_ms,
                utterance: Some(utterance),
                ..
            }) => Heard::VadEnd { utterance, at_ms },
            _ => Heard::Other,
        };
    }
    match serde_json::from_value::<TranscriptMessage>(value) {
        Ok(t) if t.is_final => Heard::Final(t),
        _ => Heard::Other,
    }
}

/// A finished turn as the contract's `Agent.latency` message, with the stages behind now.
fn latency_message(turn: &TurnDone, behind: Vec<String>) -> TurnLatency {
    let ms = |us: u64| us as f64 / 1000.0;
    TurnLatency {
        kind: "voice".into(),
        speech_end_ms: turn.speech_end_us / 1000,
        vad_ms: ms(turn.vad_us),
        transcript_ms: ms(turn.transcript_us),
        rule_ms: ms(turn.rule_us),
        reply_ms: ms(turn.reply_us),
        total_ms: ms(turn.total_us),
        behind,
    }
}

/// A finished turn: its figures, its `Agent.latency` message and, with telemetry on, its spans.
fn finished(
    figures: &Figures,
    pace: &mut Pace,
    latency: &flow::Publisher,
    telemetry: &flow_telemetry::Telemetry,
    turn: &TurnDone,
) {
    figures.reply(turn);
    for change in pace.turn(turn) {
        let (stage, median_ms, budget_ms) = (change.stage, change.median_ms, change.budget_ms);
        if change.behind {
            warn!(
                stage,
                median_ms,
                budget_ms,
                "this machine is behind on the turn's {stage}: the configured models or other work are too slow for it"
            );
        } else {
            info!(
                stage,
                median_ms, budget_ms, "the turn's {stage} keeps up again"
            );
        }
        figures
            .behind
            .get_or_create(&StageLabel { stage })
            .set(i64::from(pace.is_behind(stage)));
    }
    if telemetry.is_on() {
        for span in spans::turn_spans(turn) {
            telemetry.record(span);
        }
    }
    // One small message per turn; a full send queue drops it (counted by the SDK).
    let message = serde_json::to_vec(&latency_message(turn, pace.behind())).unwrap_or_default();
    let _ = latency.try_publish(message);
}

/// The first chunk of a reply's speech: `[utterance u32][offset u32][PCM]` with offset 0.
fn starts_utterance(payload: &[u8]) -> bool {
    payload.len() > 8 && payload[4..8] == [0, 0, 0, 0]
}

/// The utterance number a speech chunk carries (its first four bytes, little-endian), as the page reads it.
fn speech_utterance(payload: &[u8]) -> u64 {
    payload
        .first_chunk::<4>()
        .map_or(0, |b| u64::from(u32::from_le_bytes(*b)))
}

impl Module for ObserverModule {
    fn name(&self) -> &'static str {
        "observer"
    }

    fn check(&self, params: &serde_json::Value) -> anyhow::Result<()> {
        observer_params(params).map(drop)
    }

    fn run(self: Box<Self>, mut ctx: ModuleContext) -> ModuleFuture {
        Box::pin(async move {
            let figures = Figures::register(&ctx.metrics());
            let telemetry = ctx.telemetry();
            let client = ctx.client.clone();
            let mut events = client.events();
            let transcripts = client.subscribe(channels::TRANSCRIPT.name).await?;
            let detections = client.subscribe(channels::DETECTIONS.name).await?;
            let rules = client.subscribe(channels::RULES.name).await?;
            let speech = client.subscribe(channels::SPEECH.name).await?;
            let playback = client.subscribe(channels::PLAYBACK.name).await?;
            let chat_reply = client.subscribe(channels::CHAT_REPLY.name).await?;
            // The last reply's speech utterance and turn, until its page says it is heard.
            let mut replied: Option<(u64, TurnDone)> = None;
            let latency = client
                .publisher(channels::LATENCY.name, channels::headers::LATENCY)
                .await?;
            // Claims already open when the module starts are counted from their next change.
            let mut claims = Claims::default();
            let mut turns = Turns::default();
            let mut pace = Pace::new(observer_params(&ctx.params)?.budgets_ms);
            loop {
                tokio::select! {
                    // In this order when several are ready (a loaded machine wakes the observer late): a turn's
                    // transcript before the rule it fired, or the turn is not matched.
                    biased;
                    _ = ctx.stopped() => return Ok(()),
                    Some(d) = transcripts.recv() => match heard(&d.payload) {
                        Heard::VadEnd { utterance, at_ms } => {
                            figures.stages(turns.vad_end(&utterance, at_ms, d.ts_us));
                        }
                        Heard::Final(t) => {
                            let label = SatelliteLabel { satellite: t.satellite.clone() };
                            figures.asr_utterances.get_or_create(&label).inc();
                            figures
                                .asr_processing
                                .get_or_create(&label)
                                .observe(t.processing_ms as f64 / 1000.0);
                            figures.stages(turns.transcript(&t.utterance, t.trace.as_deref(), d.ts_us));
                        }
                        Heard::Other => {}
                    },
                    Some(d) = detections.recv() => figures.detections(&d),
                    Some(d) = chat_reply.recv() => figures.chat_end(&d),
                    Some(d) = playback.recv() => {
                        if let Ok(started) = serde_json::from_slice::<PlaybackStarted>(&d.payload)
                            && let Some((_, turn)) = replied.take_if(|(u, _)| *u == started.utterance)
                        {
                            let heard_us = (started.at_ms.max(0.0) * 1000.0) as u64;
                            telemetry.record(spans::playback_span(&turn, heard_us));
                        }
                    }
                    Some(d) = rules.recv() => {
                        if let Ok(r) = serde_json::from_slice::<RuleChange>(&d.payload) {
                            let on_speech = r.because.iter().any(|b| b.starts_with("heard("));
                            let at_ms = u64::try_from(r.ts_ms).unwrap_or(0);
                            let (stages, done) = turns.rule(&r.rule, at_ms, on_speech);
                            figures.stages(stages);
                            if let Some(turn) = done {
                                finished(&figures, &mut pace, &latency, &telemetry, &turn);
                                // Its speech utterance is not known here: no playback span for this turn.
                            }
                        }
                    }
                    Some(d) = speech.recv() => {
                        if starts_utterance(&d.payload)
                            && let Some(turn) = turns.reply_audio(d.ts_us)
                        {
                            finished(&figures, &mut pace, &latency, &telemetry, &turn);
                            if telemetry.is_on() {
                                replied = Some((speech_utterance(&d.payload), turn));
                            }
                        }
                    }
                    event = events.recv() => match event {
                        Ok(ClientEvent::ChannelAdded(info)) => {
                            if let Some(u) = info.name.strip_prefix(channels::ASR_CLAIM_PREFIX) {
                                let header = serde_json::from_str(&info.header).unwrap_or_default();
                                figures.claim(claims.added(u, &claims::holder(&header, &info.owner)));
                            }
                        }
                        Ok(ClientEvent::HeaderChanged { name, header, .. }) => {
                            if let Some(u) = name.strip_prefix(channels::ASR_CLAIM_PREFIX) {
                                let header: serde_json::Value =
                                    serde_json::from_str(&header).unwrap_or_default();
                                if header.get("done").and_then(|d| d.as_bool()) == Some(true) {
                                    claims.done(u);
                                }
                            }
                        }
                        Ok(ClientEvent::ChannelRemoved { name, .. }) => {
                            if let Some(u) = name.strip_prefix(channels::ASR_CLAIM_PREFIX)
                                && let Some(news) = claims.removed(u)
                            {
                                figures.claim(news);
                            }
                        }
                        Ok(_) => {}
                        // Missed events only cost a count or two; the channel of news goes on.
                        Err(RecvError::Lagged(n)) => {
                            tracing::debug!(missed = n, "observer fell behind the hub's channel news");
                        }
                        Err(RecvError::Closed) => return Ok(()),
                    },
                    else => return Ok(()),
                }
            }
        })
    }
}
