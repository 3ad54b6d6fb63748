//! OpenTelemetry traces of a spoken turn through real processes (docs/telemetry.md): a real `robot-agent` on the
//! default rule program, a real `whisper-sat` and a real `llm-sat`, each exporting over OTLP/HTTP to a test
//! collector that decodes the exports with OpenTelemetry's own protobuf definitions. One trace per turn: the root
//! and its stages from robot-agent, the decode from whisper-sat and the generation from llm-sat, joined by the trace
//! context the messages carry, the stages adding up to `Agent.latency`'s figure. With telemetry switched off,
//! nothing is exported.
//!
//! Needs the binaries (`cargo build --workspace --all-targets`), the models (`make model`, `make model-llm`) and
//! espeak-ng.

use std::collections::HashSet;
use std::path::PathBuf;
use std::time::Duration;

use agent_contract::channels as ch;
use agent_contract::latency::TurnLatency;
use agent_tests::otlp::{Collector, Received};
use agent_tests::satellite::LlmSat;
use agent_tests::spoken::{say, silence, write_wav};
use agent_tests::{Agent, AgentOptions, DataDir, Satellite, recv_until, run};
use anyhow::Context;

/// Whisper and the model share two cores, possibly beside a build: waits are generous, never timed.
const PATIENCE: Duration = Duration::from_secs(180);
/// Spans are sent in batches this often (ms) in these tests, instead of every 5 s.
const BATCH_MS: &str = "200";
/// Spans stamped by different processes (and the hub's stamps) on one machine's clock agree this closely.
const CLOCKS_MS: f64 = 10.0;

/// The spans robot-agent records for a turn answered by the model.
const AGENT_SPANS: [&str; 6] = [
    "turn",
    "voice_activity",
    "transcription",
    "rule",
    "reply",
    "synthesis",
];

/// An open question no rule catches, so the catch-all hands it to the model.
const OPEN_QUESTION: &str = "Why is the sky blue?";
/// A question a rule answers itself.
const RULE_QUESTION: &str = "What time is it?";

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A robot-agent on the shipped rule program with `telemetry` as its `[telemetry]` section and `env` set; no
/// camera, so nothing but the voice moves the brain.
async fn agent(dir: &DataDir, telemetry: &str, env: &[(&str, &str)]) -> anyhow::Result<Agent> {
    let program = repo().join("config/brain.tr");
    let config = format!(
        "[modules.brain]\nprogram = {:?}\nchat_thinking_ms = 0\n[modules.vision]\nenabled = false\n{telemetry}",
        program.display().to_string()
    );
    let opts = AgentOptions {
        config: Some(config),
        env: env
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect(),
        ..AgentOptions::default()
    };
    let agent = Agent::start_with(dir, opts).await?;
    agent
        .output
        .wait_for("brain: program loaded", 1, PATIENCE)
        .await
        .context("the brain did not load its program")?;
    Ok(agent)
}

/// Says `question` into the agent's microphone in real time and returns the turn's `Agent.latency` message.
async fn spoken_turn(agent: &Agent, dir: &DataDir, question: &str) -> anyhow::Result<TurnLatency> {
    let watcher = agent.client("telemetry-test").await?;
    let latency = watcher.subscribe(ch::LATENCY.name).await?;
    let wav = dir.path().join("question.wav");
    write_wav(
        &wav,
        &[silence(500), say(question, dir.path())?, silence(500)].concat(),
    )?;
    let publishing = tokio::spawn(run(agent.microphone(&wav, 1500)?, b"", PATIENCE));
    let turn = recv_until(&latency, "the turn's latency", PATIENCE, |d| {
        serde_json::from_slice::<TurnLatency>(&d.payload).ok()
    })
    .await?;
    publishing.await??.ok()?;
    Ok(turn)
}

/// The one span named `name` among `spans`.
fn one<'a>(spans: &'a [Received], name: &str) -> anyhow::Result<&'a Received> {
    let found: Vec<&Received> = spans.iter().filter(|s| s.span.name == name).collect();
    match found[..] {
        [span] => Ok(span),
        _ => anyhow::bail!("{} spans named {name}: {found:#?}", found.len()),
    }
}

fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_spoken_turn_exports_one_trace_across_robot_agent_whisper_sat_and_llm_sat()
-> anyhow::Result<()> {
    let mut collector = Collector::start().await?;
    let url = collector.url();
    let batch = [("OTEL_BSP_SCHEDULE_DELAY", BATCH_MS)];
    let dir = DataDir::new()?;
    let agent = agent(&dir, &format!("[telemetry]\notlp = {url:?}\n"), &batch).await?;
    let _asr = Satellite::start_with_env(&agent, "trace-asr", &["--otlp", &url], &batch).await?;
    let _llm =
        LlmSat::start_with_env(&agent, &["--max-sentences", "2", "--otlp", &url], &batch).await?;

    let latency = spoken_turn(&agent, &dir, OPEN_QUESTION).await?;
    let satellites_spans = [
        "whisper.decode",
        "llm.generate",
        "llm.first_token",
        "llm.sentence",
    ];
    let wanted: Vec<&str> = AGENT_SPANS.into_iter().chain(satellites_spans).collect();
    let spans = collector
        .until(PATIENCE, "every span of the turn", |got| {
            let names: HashSet<&str> = got.iter().map(|s| s.span.name.as_str()).collect();
            wanted.iter().all(|w| names.contains(w))
        })
        .await?;
    // Anything of the turn still in a batch on its way.
    let late = collector.drain(Duration::from_secs(2)).await;
    let spans: Vec<Received> = spans.into_iter().chain(late).collect();

    // One trace: every span in the root's.
    let root = one(&spans, "turn")?;
    assert_eq!(root.parent_id(), "", "the turn is the root");
    let trace = root.trace_id();
    let foreign: Vec<&Received> = spans.iter().filter(|s| s.trace_id() != trace).collect();
    assert!(
        foreign.is_empty(),
        "spans outside the turn's trace: {foreign:#?}"
    );

    // Each process exported its own part, under its service name.
    let service_of = |name: &str| one(&spans, name).map(|s| s.service.clone());
    for name in AGENT_SPANS {
        assert_eq!(service_of(name)?, "robot-agent", "{name}");
    }
    assert_eq!(service_of("whisper.decode")?, "whisper-sat");
    assert_eq!(service_of("llm.generate")?, "llm-sat");
    assert_eq!(
        one(&spans, "whisper.decode")?
            .attribute("satellite")
            .as_deref(),
        Some("trace-asr")
    );

    // Parents across processes: the ids carried in the transcript, the chat request and the speech request.
    let id = |name: &str| one(&spans, name).map(Received::span_id);
    let parent = |name: &str| one(&spans, name).map(Received::parent_id);
    for stage in ["voice_activity", "transcription", "rule", "reply"] {
        assert_eq!(
            parent(stage)?,
            root.span_id(),
            "{stage} hangs under the turn"
        );
    }
    assert_eq!(
        parent("whisper.decode")?,
        id("transcription")?,
        "whisper-sat's decode under robot-agent's stage"
    );
    assert_eq!(
        parent("llm.generate")?,
        id("reply")?,
        "llm-sat's generation under robot-agent's reply"
    );
    assert_eq!(
        parent("synthesis")?,
        id("reply")?,
        "the synthesis under the reply"
    );
    assert_eq!(parent("llm.first_token")?, id("llm.generate")?);
    let sentences: Vec<&Received> = spans
        .iter()
        .filter(|s| s.span.name == "llm.sentence")
        .collect();
    assert!(
        sentences
            .iter()
            .all(|s| s.parent_id() == id("llm.generate").unwrap_or_default()),
        "{sentences:#?}"
    );

    // The stages in order, end to end, adding up to the turn and to Agent.latency's figure.
    let stages = ["voice_activity", "transcription", "rule", "reply"];
    let mut at = root.start_ns();
    for stage in stages {
        let s = one(&spans, stage)?;
        assert_eq!(
            s.start_ns(),
            at,
            "{stage} starts where the stage before it ended"
        );
        at = s.end_ns();
    }
    assert_eq!(at, root.end_ns(), "the reply ends the turn");
    let sum: f64 = stages
        .iter()
        .map(|s| one(&spans, s).map_or(0.0, Received::duration_ms))
        .sum();
    let figures = [
        ("turn", root.duration_ms(), latency.total_ms),
        ("stages", sum, latency.total_ms),
        (
            "voice_activity",
            one(&spans, "voice_activity")?.duration_ms(),
            latency.vad_ms,
        ),
        (
            "transcription",
            one(&spans, "transcription")?.duration_ms(),
            latency.transcript_ms,
        ),
        ("rule", one(&spans, "rule")?.duration_ms(), latency.rule_ms),
        (
            "reply",
            one(&spans, "reply")?.duration_ms(),
            latency.reply_ms,
        ),
    ];
    for (what, span_ms, latency_ms) in figures {
        assert!(
            (span_ms - latency_ms).abs() <= CLOCKS_MS,
            "{what}: {span_ms:.3} ms in the trace, {latency_ms:.3} ms on Agent.latency ({latency:?})"
        );
    }
    assert_eq!(
        ms(root.start_ns()).round() as u64,
        latency.speech_end_ms,
        "the turn starts at the end of speech"
    );

    // The work inside the reply, in order across processes: the request after the rule, the first token before
    // the first sentence, the speech asked for after it and ready by the end of the reply.
    let rule = one(&spans, "rule")?;
    let generate = one(&spans, "llm.generate")?;
    let first_token = one(&spans, "llm.first_token")?;
    let synthesis = one(&spans, "synthesis")?;
    let reply = one(&spans, "reply")?;
    let first_sentence = sentences
        .iter()
        .find(|s| s.attribute("index").as_deref() == Some("0"))
        .context("no first sentence span")?;
    let before = |a: u64, b: u64| ms(a) <= ms(b) + CLOCKS_MS;
    // A reply generated speculatively at the pause and adopted by the rule (`speculated`) was asked for before
    // the rule fired, but never before the speech ended.
    if generate.attribute("speculated").as_deref() == Some("true") {
        assert!(
            before(root.start_ns(), generate.start_ns()),
            "the speculative request came before the end of speech"
        );
    } else {
        assert!(
            before(rule.end_ns(), generate.start_ns()),
            "the model was asked before the rule fired"
        );
    }
    assert_eq!(first_token.start_ns(), generate.start_ns());
    assert!(
        first_token.end_ns() <= first_sentence.end_ns(),
        "a sentence before the first token"
    );
    assert!(
        before(first_sentence.end_ns(), synthesis.start_ns()),
        "speech asked for before its sentence"
    );
    assert!(
        before(synthesis.end_ns(), reply.end_ns()),
        "the first audio after the reply ended"
    );

    // Logs carry the trace id.
    assert!(
        !agent.output.matching(&trace).is_empty(),
        "robot-agent's log does not name the trace {trace}"
    );
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_telemetry_switched_off_a_turn_exports_nothing() -> anyhow::Result<()> {
    let mut collector = Collector::start().await?;
    let url = collector.url();
    // The collector is named, and the standard switch turns telemetry off over it.
    let off = [
        ("OTEL_EXPORTER_OTLP_ENDPOINT", url.as_str()),
        ("OTEL_SDK_DISABLED", "true"),
        ("OTEL_BSP_SCHEDULE_DELAY", BATCH_MS),
    ];
    let dir = DataDir::new()?;
    let agent = agent(&dir, "", &off).await?;
    let _asr = Satellite::start_with_env(&agent, "quiet-asr", &[], &off).await?;
    let latency = spoken_turn(&agent, &dir, RULE_QUESTION).await?;
    assert!(latency.total_ms > 0.0, "{latency:?}");
    // Several batch periods after the turn: nothing came.
    let got = collector.drain(Duration::from_secs(2)).await;
    assert!(got.is_empty(), "exported with telemetry off: {got:#?}");
    assert!(
        agent
            .output
            .matching("telemetry: exporting traces")
            .is_empty()
    );
    Ok(())
}
