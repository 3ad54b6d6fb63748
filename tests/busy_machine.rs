//! On a machine shared with other work, the agent still hears every word and answers.
//!
//! Two busy loops at normal priority (a robot's navigation, a build) take both cores while a real `robot-agent` on
//! its embedded defaults (as `make run` starts it), a real `whisper-sat` and a real `llm-sat` serve two spoken
//! questions streamed in real time: one a rule answers ("What time is it?") and one the model answers ("Why is the
//! sky blue?"). Each must be heard whole and answered aloud after it was heard. Only the order of events is asserted,
//! never a duration. And when the machine cannot keep up, the agent says which stage is behind.

use agent_contract::channels as ch;
use std::time::Duration;

use agent_tests::satellite::LlmSat;
use agent_tests::spoken::{say, silence, words, write_wav};
use agent_tests::{Agent, DataDir, Satellite, json_message, next_payload, run};
use anyhow::Context;
use serde_json::Value;

/// Everything shares two cores with two busy loops: waits are generous, never timed.
const PATIENCE: Duration = Duration::from_secs(300);

const RULE_QUESTION: &str = "What time is it?";
const OPEN_QUESTION: &str = "Why is the sky blue?";

/// A loop that spins until dropped, at the priority every process starts with.
struct BusyLoop(std::process::Child);

impl BusyLoop {
    fn start() -> anyhow::Result<BusyLoop> {
        let child = std::process::Command::new("sh")
            .args(["-c", "while :; do :; done"])
            .spawn()
            .context("starting a busy loop")?;
        Ok(BusyLoop(child))
    }
}

impl Drop for BusyLoop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// What the watcher saw, in order.
#[derive(Debug)]
enum Seen {
    Transcript(String),
    Rule(String),
    Reply(Value),
    Speech,
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn beside_two_busy_loops_both_questions_are_heard_whole_and_answered_aloud()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::start(&dir).await?;
    let watcher = agent.client("busy-machine-test").await?;
    let transcript = watcher.subscribe(ch::TRANSCRIPT.name).await?;
    let rules = watcher.subscribe(ch::RULES.name).await?;
    let reply = watcher.subscribe(ch::CHAT_REPLY.name).await?;
    let speech = watcher.subscribe(ch::SPEECH.name).await?;
    let _asr = Satellite::start(&agent, "busy-asr").await?;
    let _llm = LlmSat::start(&agent, &["--max-sentences", "2"]).await?;
    let _loops = [BusyLoop::start()?, BusyLoop::start()?];

    let wav = dir.path().join("questions.wav");
    write_wav(
        &wav,
        &[
            silence(500),
            say(RULE_QUESTION, dir.path())?,
            silence(6000),
            say(OPEN_QUESTION, dir.path())?,
            silence(500),
        ]
        .concat(),
    )?;
    let publishing = tokio::spawn(run(agent.microphone(&wav, 1500)?, b"", PATIENCE));

    let mut seen: Vec<Seen> = Vec::new();
    let heard = |seen: &[Seen], q: &str| {
        seen.iter()
            .position(|s| matches!(s, Seen::Transcript(t) if t.contains(&words(q))))
    };
    let waited = tokio::time::timeout(PATIENCE, async {
        loop {
            let next = tokio::select! {
                // A transcript before the rule it fired when both are waiting (the busy loops delay this test).
                biased;
                p = next_payload(&transcript) => json_message(&p?)
                    .filter(|v| v["final"] == true)
                    .and_then(|v| v["text"].as_str().map(|t| Seen::Transcript(words(t)))),
                p = next_payload(&rules) => json_message(&p?)
                    .and_then(|v| v["rule"].as_str().map(|r| Seen::Rule(r.to_owned()))),
                p = next_payload(&reply) => json_message(&p?).map(Seen::Reply),
                p = next_payload(&speech) => { p?; Some(Seen::Speech) },
            };
            if let Some(next) = next {
                seen.push(next);
            }
            let ended = seen
                .iter()
                .any(|s| matches!(s, Seen::Reply(v) if v["event"] == "end"));
            if let Some(open) = heard(&seen, OPEN_QUESTION)
                && ended
                && seen[open..].iter().any(|s| matches!(s, Seen::Speech))
            {
                return anyhow::Ok(());
            }
        }
    })
    .await;
    let finals: Vec<&Seen> = seen
        .iter()
        .filter(|s| matches!(s, Seen::Transcript(_)))
        .collect();
    waited.with_context(|| {
        format!("the second question was not answered; transcripts: {finals:?}")
    })??;
    publishing.await??.ok()?;

    // Both questions heard whole, each answered aloud after it was heard: the rule's by the time rule, the open one
    // by the model.
    let rule_at = heard(&seen, RULE_QUESTION)
        .with_context(|| format!("{RULE_QUESTION:?} was not heard whole: {finals:?}"))?;
    let open_at = heard(&seen, OPEN_QUESTION).context("the open question")?;
    let fired = seen[rule_at..]
        .iter()
        .position(|s| matches!(s, Seen::Rule(r) if r.contains("answer.time")))
        .with_context(|| format!("the time rule did not fire after the question: {seen:?}"))?;
    assert!(
        seen[rule_at + fired..open_at]
            .iter()
            .any(|s| matches!(s, Seen::Speech)),
        "the time was not spoken before the next question: {seen:?}"
    );
    assert!(
        seen[open_at..]
            .iter()
            .any(|s| matches!(s, Seen::Reply(v) if v["event"] == "sentence")),
        "the model did not answer the open question: {seen:?}"
    );
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stage_over_its_budget_is_named_in_the_log_in_metrics_and_in_the_turns_latency()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    // The silence hangover is never under a millisecond: with that budget every turn's voice activity is behind,
    // as it would be on a machine too slow for its models.
    let agent = Agent::start_configured(
        &dir,
        "[modules.observer]\nbudgets_ms = { vad = 1 }\n",
        "module started",
    )
    .await?;
    let watcher = agent.client("pace-test").await?;
    let latency = watcher.subscribe(ch::LATENCY.name).await?;
    let _asr = Satellite::start(&agent, "pace-asr").await?;
    let wav = dir.path().join("three-questions.wav");
    let question = say(RULE_QUESTION, dir.path())?;
    let mut samples = silence(500);
    // Four questions for three measured turns: the observer has been seen to miss one turn in a run (issue 49's
    // closing note; under investigation), and this test is about the stage being named, not about that.
    for _ in 0..4 {
        samples.extend_from_slice(&question);
        samples.extend(silence(4000));
    }
    write_wav(&wav, &samples)?;
    let publishing = tokio::spawn(run(agent.microphone(&wav, 1500)?, b"", PATIENCE));

    // Three turns measured: the first two are not judged yet, the third names the stage.
    let mut turns = Vec::new();
    let deadline = tokio::time::Instant::now() + PATIENCE;
    while turns.len() < 3 {
        let p = tokio::time::timeout_at(deadline, next_payload(&latency))
            .await
            .with_context(|| format!("only {} turns measured: {turns:?}", turns.len()))??;
        turns.extend(json_message(&p));
    }
    publishing.await??.ok()?;
    assert!(turns[0].get("behind").is_none(), "{turns:?}");
    assert_eq!(turns[2]["behind"], serde_json::json!(["vad"]), "{turns:?}");
    agent
        .output
        .wait_for("this machine is behind on the turn's vad", 1, PATIENCE)
        .await?;
    let samples = agent_tests::metrics::parse(&agent_tests::metrics::scrape(&agent).await?).await?;
    assert_eq!(
        agent_tests::metrics::value(&samples, "agent_turn_stage_behind", &[("stage", "vad")]),
        Some(1.0)
    );
    Ok(())
}
