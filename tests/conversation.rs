//! The whole voice loop through real processes: a real human recording streamed in real time on `Agent.audio`, a
//! real `whisper-sat` (tiny.en) hearing it, the brain choosing a reply and the TTS module speaking it. The test
//! waits for each step on the hub: voice activity and the final transcript on `Agent.transcript`, the rule change
//! on `Agent.rules`, reply PCM on `Agent.speech` and visemes on `Agent.avatar`.
//!
//! Needs the binaries (`cargo build -p robot-agent -p flowctl -p whisper-sat`) and the model (`make model`).

use agent_contract::channels as ch;
use std::time::Duration;

use agent_tests::{Agent, DataDir, Satellite, fixture, run};
use anyhow::Context;
use flow::Subscription;
use serde_json::Value;

/// Everything here runs on two shared cores, possibly beside a build: waits are generous, never timed.
const PATIENCE: Duration = Duration::from_secs(180);

/// What the test has seen so far, in the order it arrived.
#[derive(Debug, Default)]
struct Seen {
    vad_start: Option<Value>,
    vad_end: Option<Value>,
    transcript: Option<Value>,
    rule_change: Option<Value>,
    speech_bytes: usize,
    visemes: usize,
}

impl Seen {
    fn complete(&self) -> bool {
        self.vad_start.is_some()
            && self.vad_end.is_some()
            && self.transcript.is_some()
            && self.rule_change.is_some()
            && self.speech_bytes > 0
            && self.visemes > 0
    }

    fn transcript_message(&mut self, v: Value) {
        match v["vad"].as_str() {
            Some("start") if self.vad_start.is_none() => self.vad_start = Some(v),
            Some("end") if self.vad_start.is_some() && self.vad_end.is_none() => {
                self.vad_end = Some(v);
            }
            Some(_) => {}
            None if v["final"] == true && self.transcript.is_none() => self.transcript = Some(v),
            None => {}
        }
    }

    /// A rule trace counts when hearing something made it true. (Its arrival is not compared with the transcript's:
    /// the two come on different subscriptions, whose order the test cannot see.)
    fn rule_trace(&mut self, v: Value) {
        let heard = v["because"].as_array().is_some_and(|facts| {
            facts
                .iter()
                .any(|f| f.as_str().is_some_and(|f| f.starts_with("heard(")))
        });
        if heard && self.rule_change.is_none() {
            self.rule_change = Some(v);
        }
    }

    /// Nothing else makes the agent speak here (no camera, so no greeting): any visemes belong to the answer.
    fn avatar_command(&mut self, v: &Value) {
        if v["cmd"] == "visemes" {
            self.visemes += v["items"].as_array().map_or(0, Vec::len);
        }
    }
}

fn json(payload: &[u8]) -> Option<Value> {
    serde_json::from_slice(payload).ok()
}

async fn next(sub: &Subscription) -> anyhow::Result<bytes::Bytes> {
    Ok(sub
        .recv()
        .await
        .with_context(|| format!("{} ended", sub.name()))?
        .payload)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_spoken_question_gets_a_spoken_answer() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    // The shipped program; no camera here: the vision module stays off so that nothing but the voice moves the
    // brain.
    let program = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/brain.tr");
    let config = format!(
        "[modules.brain]\nprogram = {:?}\n[modules.vision]\nenabled = false\n",
        program.display().to_string()
    );
    let agent = Agent::start_configured(&dir, &config, "brain: program loaded").await?;
    let watcher = agent.client("conversation-test").await?;
    let transcript = watcher.subscribe(ch::TRANSCRIPT.name).await?;
    let rules = watcher.subscribe(ch::RULES.name).await?;
    let speech = watcher.subscribe(ch::SPEECH.name).await?;
    let avatar = watcher.subscribe(ch::AVATAR.name).await?;
    let _satellite = Satellite::start(&agent, "conversation-asr").await?;

    // A real human recording, 20 ms chunks paced in real time, then silence so the utterance ends.
    let mut publish = agent.flowctl()?;
    publish
        .arg("pub-wav")
        .arg(ch::AUDIO.name)
        .arg(fixture("audio/LJ001-0002.wav")?)
        .arg("--realtime")
        .arg("--tail-ms")
        .arg("1500");
    let publishing = tokio::spawn(run(publish, b"", PATIENCE));

    let mut seen = Seen::default();
    let waited = tokio::time::timeout(PATIENCE, async {
        while !seen.complete() {
            tokio::select! {
                p = next(&transcript) => {
                    if let Some(v) = json(&p?) {
                        seen.transcript_message(v);
                    }
                }
                p = next(&rules) => {
                    if let Some(v) = json(&p?) {
                        seen.rule_trace(v);
                    }
                }
                p = next(&speech) => seen.speech_bytes += p?.len(),
                p = next(&avatar) => {
                    if let Some(v) = json(&p?) {
                        seen.avatar_command(&v);
                    }
                }
            }
        }
        anyhow::Ok(())
    })
    .await;
    println!("{seen:#?}");
    waited.with_context(|| format!("the conversation stalled: {seen:#?}"))??;
    publishing.await??.ok()?;

    let (start, end, heard) = (
        seen.vad_start.context("vad start")?,
        seen.vad_end.context("vad end")?,
        seen.transcript.context("transcript")?,
    );
    let text = heard["text"].as_str().context("transcript text")?;
    assert!(!text.trim().is_empty(), "{heard}");
    assert!(
        text.to_lowercase().contains("modern"),
        "tiny.en misheard the recording: {heard}"
    );
    // The voice activity frames the transcribed utterance on the same clock.
    let at = |v: &Value| v["at_ms"].as_u64().unwrap_or(0);
    assert!(at(&start) < at(&end), "{start} {end}");
    assert_eq!(end["utterance"], heard["utterance"], "{end} {heard}");
    assert_eq!(
        Some(at(&end)),
        heard["end_us"].as_u64().map(|us| us / 1000),
        "{end} {heard}"
    );
    // The brain acted on what it heard: the trace names the rule that took over.
    let rule = seen.rule_change.context("rule change")?;
    assert!(
        rule["rule"]
            .as_str()
            .is_some_and(|r| r.contains("converse")),
        "{rule}"
    );
    // Real speech: whole s16le samples.
    assert_eq!(seen.speech_bytes % 2, 0);
    metrics_tell_the_same_turn(&agent).await
}

/// `/metrics`, scraped after the turn and read by Prometheus's own parser, counts what the test just saw: every
/// stage of the turn once at least, the satellite's utterance and claim, the traffic and the connections.
async fn metrics_tell_the_same_turn(agent: &Agent) -> anyhow::Result<()> {
    use agent_tests::metrics::{parse, scrape, value};
    let whole = ("stage", "speech_end_to_reply_audio");
    let samples = tokio::time::timeout(PATIENCE, async {
        loop {
            let samples = parse(&scrape(agent).await?).await?;
            if value(&samples, "agent_conversation_seconds_count", &[whole]).unwrap_or(0.0) >= 1.0 {
                return anyhow::Ok(samples);
            }
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    })
    .await
    .context("the observer never counted the turn")??;
    for stage in [
        "speech_end_to_vad_end",
        "vad_end_to_transcript",
        "transcript_to_rule",
        "rule_to_reply_audio",
    ] {
        let n = value(
            &samples,
            "agent_conversation_seconds_count",
            &[("stage", stage)],
        );
        assert!(n >= Some(1.0), "stage {stage}: {n:?}");
    }
    let total = value(&samples, "agent_conversation_seconds_sum", &[whole]).unwrap_or(0.0);
    assert!(total > 0.0 && total < 60.0, "voice to voice took {total} s");
    let sum_of = |name: &str| -> f64 {
        samples
            .iter()
            .filter(|s| s.name == name)
            .map(|s| s.value)
            .sum()
    };
    assert!(
        sum_of("agent_asr_utterances_total") >= 1.0,
        "no utterance counted"
    );
    assert!(sum_of("agent_asr_claims_total") >= 1.0, "no claim counted");
    assert!(sum_of("agent_asr_processing_seconds_count") >= 1.0);
    // The microphone's channel went with flowctl; the satellite's transcript channel is still there.
    let heard = value(
        &samples,
        "flow_channel_messages_total",
        &[("channel", ch::TRANSCRIPT.name)],
    );
    assert!(heard >= Some(3.0), "transcript messages: {heard:?}");
    assert!(value(&samples, "flow_connections", &[("transport", "tcp")]) >= Some(2.0));
    assert!(value(&samples, "flow_connections", &[("transport", "module")]) >= Some(1.0));
    let submitted = value(
        &samples,
        "flow_service_calls_total",
        &[("service", ch::ASR_SUBMIT.name), ("outcome", "answered")],
    );
    assert!(
        submitted >= Some(1.0),
        "transcript submissions: {submitted:?}"
    );
    assert!(
        value(
            &samples,
            "flow_tick_lateness_seconds_count",
            &[("pulse", "one_sec")]
        ) >= Some(1.0)
    );
    Ok(())
}
