//! The agent in Italian, end to end through real processes: `agent.language = "it"` in the configuration, a real
//! Italian speaker (the Asterisk prompts recorded by Carlo Flora, Debian's `asterisk-core-sounds-it-wav`,
//! CC-BY-3.0) streamed in real time on `Agent.audio`, a real `whisper-sat` with the multilingual base model and the
//! Italian language token hearing it, the Italian rule program answering and the TTS module speaking the answer
//! with espeak-ng's Italian voice and its visemes.
//!
//! Needs the binaries, the base model (`make model MODEL=base`; `make test` provisions it) and the Debian package
//! (`scripts/deps.sh` installs it).

use agent_contract::channels as ch;
use std::path::{Path, PathBuf};
use std::time::Duration;

use agent_tests::{Agent, DataDir, Satellite, json_message, next_payload, run};
use anyhow::Context;

/// Two shared cores, possibly beside a build, and the base model: waits are generous, never timed.
const PATIENCE: Duration = Duration::from_secs(240);

/// Where Debian puts the Italian prompts and their transcripts.
const PROMPTS: &str = "/usr/share/asterisk/sounds/it_IT_m_Carlo";
const TRANSCRIPTS: &str = "/usr/share/doc/asterisk-core-sounds-it/core-sounds-it.txt.gz";

fn prompt(name: &str) -> anyhow::Result<PathBuf> {
    let path = Path::new(PROMPTS).join(format!("{name}.wav"));
    anyhow::ensure!(
        path.is_file(),
        "{} is missing: install asterisk-core-sounds-it-wav (scripts/deps.sh does)",
        path.display()
    );
    Ok(path)
}

/// The recording's transcript from the package's own list (`name: text` lines, gzip).
fn prompt_text(name: &str) -> anyhow::Result<String> {
    let out = std::process::Command::new("zcat")
        .arg(TRANSCRIPTS)
        .output()
        .with_context(|| format!("reading {TRANSCRIPTS} (install asterisk-core-sounds-it)"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    text.lines()
        .find_map(|l| l.strip_prefix(&format!("{name}: ")))
        .map(|t| t.trim().to_owned())
        .with_context(|| format!("no transcript of {name} in {TRANSCRIPTS}"))
}

fn base_model() -> anyhow::Result<String> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/ggml-base.bin");
    anyhow::ensure!(
        path.is_file(),
        "{} is missing: run `make model MODEL=base` (`make test` does)",
        path.display()
    );
    Ok(path.display().to_string())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn italian_speech_gets_an_italian_transcript_and_a_spoken_italian_reply() -> anyhow::Result<()>
{
    let greeting = prompt("hello")?;
    let reference = prompt_text("hello")?;
    let dir = DataDir::new()?;
    // The rule program's path is absolute because the server runs in the test's data directory; the language
    // alone picks the voice and the clock's words.
    let program = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/brain.it.tr");
    let config = format!(
        "[agent]\nlanguage = \"it\"\n[modules.brain]\nprogram = {:?}\n[modules.vision]\nenabled = false\n",
        program.display().to_string()
    );
    let agent = Agent::start_configured(&dir, &config, "brain: program loaded").await?;
    let watcher = agent.client("italian-test").await?;
    let transcripts = watcher.subscribe(ch::TRANSCRIPT.name).await?;
    let rules = watcher.subscribe(ch::RULES.name).await?;
    let avatar = watcher.subscribe(ch::AVATAR.name).await?;
    let model = base_model()?;
    let _satellite = Satellite::start_with(
        &agent,
        "italian-asr",
        &["--model", model.as_str(), "--language", "it"],
    )
    .await?;

    let publish = agent.microphone(&greeting, 1500)?;
    let publishing = tokio::spawn(run(publish, b"", PATIENCE));

    let (mut heard, mut rule, mut caption) = (None, None, None);
    let mut visemes: Vec<String> = Vec::new();
    // The reply's visemes come a sentence at a time; "Ciao! Come posso aiutarti?" has a score of mouth shapes.
    // Once the turn is complete, the reply is over when no viseme has come for a few seconds (or its RR has).
    let mut last_viseme = tokio::time::Instant::now();
    tokio::time::timeout(PATIENCE, async {
        loop {
            let turn = heard.is_some() && rule.is_some() && caption.is_some() && !visemes.is_empty();
            if turn && (visemes.iter().any(|v| v == "RR") || last_viseme.elapsed() > Duration::from_secs(4)) {
                break;
            }
            tokio::select! {
                () = tokio::time::sleep(Duration::from_millis(250)) => {}
                p = next_payload(&transcripts) => {
                    if let Some(v) = json_message(&p?) && v["final"] == true {
                        heard = Some(v);
                    }
                }
                p = next_payload(&rules) => {
                    if let Some(v) = json_message(&p?)
                        && v["rule"].as_str().is_some_and(|r| r.starts_with("main.converse"))
                    {
                        rule = Some(v);
                    }
                }
                p = next_payload(&avatar) => {
                    if let Some(v) = json_message(&p?) {
                        match v["cmd"].as_str() {
                            Some("say") => caption = Some(v),
                            Some("visemes") => {
                                last_viseme = tokio::time::Instant::now();
                                visemes.extend(
                                v["items"]
                                    .as_array()
                                    .into_iter()
                                    .flatten()
                                    .filter_map(|item| item["v"].as_str().map(str::to_owned)),
                                );
                            }
                            _ => {}
                        }
                    }
                }
            }
        }
        anyhow::Ok(())
    })
    .await
    .with_context(|| format!("no full Italian turn: heard {heard:?}, rule {rule:?}, caption {caption:?}, visemes {visemes:?}"))??;
    publishing.await??.ok()?;

    let heard = heard.context("no transcript")?;
    println!("heard {heard}\nrule {rule:?}\ncaption {caption:?}\nvisemes {visemes:?}");
    assert_eq!(heard["model"], "base");
    let text = heard["text"].as_str().unwrap_or_default().to_lowercase();
    // The recording says "Ciao." (the package's transcript): the Italian token makes Whisper write it so.
    assert!(
        text.contains(&reference.trim_end_matches('.').to_lowercase()),
        "heard {text:?} for {reference:?}"
    );
    let rule = rule.context("no rule change")?;
    assert_eq!(rule["rule"], "main.converse > answer.hello", "{rule}");
    let caption = caption.context("no caption")?;
    assert_eq!(caption["text"], "Ciao! Come posso aiutarti?");
    // The Italian voice speaks it: espeak-ng's Italian says "aiutarti" with a trilled r (ajʊtˈartɪ, the RR mouth
    // shape), where its English letter-to-sound rules say "ˈeɪjuːtˌɑːti" and the whole reply has no r at all.
    assert!(
        visemes.iter().any(|v| v == "RR") && visemes.iter().any(|v| v == "CH"),
        "the reply's visemes are not those of the Italian voice: {visemes:?}"
    );
    Ok(())
}
