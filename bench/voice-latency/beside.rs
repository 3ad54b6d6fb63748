//! The rule path's voice to voice beside other work (issue 47), in one run: quiet; with the agent's own page open
//! in headless Chromium on the same machine (its default avatar choice, without a GPU; no microphone or camera, so
//! the benchmark's microphone stays the only one: the page draws, plays the replies and moves the avatar); and beside
//! two busy loops at normal priority (a robot's navigation, a build). Each condition says the same rule questions and,
//! with llm-sat there, the same open questions the model answers; words lost counts the words of each question
//! missing from its final transcript.
//!
//! A fourth condition, `busy_unit`, is the busy one with the server and the speech satellite at the level the systemd
//! units give them (`Nice=-5`, docs/deploy.md), set on every thread of theirs (each keeps its distance: the vision
//! thread stays 15 levels below) where this user may raise priorities, and skipped where it may not.

use std::time::Duration;

use agent_tests::browser_chromium::{Chromium, Devices};
use agent_tests::spoken::words;
use anyhow::Context;
use tokio::sync::mpsc;

use crate::report::quantile;
use crate::speech_clip::{Clip, Say};
use crate::watch::Watcher;

/// Targets: with the page, at most 1.3x the quiet p50; with the two loops, at most 2x.
const PAGE_TARGET: f64 = 1.3;
const BUSY_TARGET: f64 = 2.0;
/// How long a condition settles before its first question (the page loads, the loops take the cores).
const SETTLE: Duration = Duration::from_secs(8);
/// How long a rule question may take from the end of speech to the reply before it counts as lost.
const RULE_PATIENCE: Duration = Duration::from_secs(60);
/// A model's reply of two or three sentences, generated and spoken, on a loaded machine fits well within this.
const MODEL_PATIENCE: Duration = Duration::from_secs(120);

/// The systemd units' level for the turn's processes.
const UNIT_NICE: i32 = -5;

/// What runs beside the agent during a condition; dropped, it stops.
enum Beside {
    Quiet,
    Page(Box<Chromium>),
    Busy(Vec<std::process::Child>),
}

/// Moves every thread of `pids` by `delta` nice levels (`renice`); false where that is not allowed.
fn renice(pids: &[u32], delta: i32) -> bool {
    let mut ok = true;
    for pid in pids {
        let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
            continue;
        };
        for task in tasks.flatten() {
            let tid = task.file_name().to_string_lossy().into_owned();
            let Some(nice) = std::fs::read_to_string(format!("/proc/{pid}/task/{tid}/stat"))
                .ok()
                .and_then(|s| {
                    let rest = s.rsplit_once(')')?.1.to_owned();
                    rest.split_whitespace().nth(16)?.parse::<i32>().ok()
                })
            else {
                continue;
            };
            let set = std::process::Command::new("renice")
                .args(["-n", &(nice + delta).to_string(), "-p", &tid])
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .status();
            ok &= set.is_ok_and(|s| s.success());
        }
    }
    ok
}

impl Beside {
    async fn start(name: &str, page_url: &str) -> anyhow::Result<Beside> {
        Ok(match name {
            "page" => {
                let browser =
                    Chromium::launch_with_flags(&Devices::Absent, &["--enable-unsafe-swiftshader"])
                        .await?;
                let tab = browser.open(page_url).await?;
                browser
                    .wait_for(
                        &tab,
                        "window.agentDebug && agentDebug.connection === 'open'",
                        Duration::from_secs(60),
                    )
                    .await
                    .context("the page did not connect")?;
                Beside::Page(Box::new(browser))
            }
            "busy" | "busy_unit" => Beside::Busy(
                (0..2)
                    .map(|_| {
                        std::process::Command::new("sh")
                            .args(["-c", "while :; do :; done"])
                            .spawn()
                            .context("starting a busy loop")
                    })
                    .collect::<anyhow::Result<_>>()?,
            ),
            _ => Beside::Quiet,
        })
    }

    async fn stop(self) {
        match self {
            Beside::Quiet => {}
            Beside::Page(browser) => browser.quit().await,
            Beside::Busy(mut loops) => {
                for l in &mut loops {
                    let _ = l.kill();
                    let _ = l.wait();
                }
            }
        }
    }
}

/// The questions each condition says: rule ones, and open ones for the model (none without llm-sat).
pub struct Questions<'a> {
    pub rule: &'a [(Clip, &'a str)],
    pub model: &'a [(Clip, &'a str)],
}

/// One condition's figures on one path (`rule` or `model`).
#[derive(Debug, Default)]
pub struct Condition {
    pub name: &'static str,
    pub path: &'static str,
    pub voice_to_voice_ms: Vec<f64>,
    pub lost_runs: usize,
    pub words: usize,
    pub words_lost: usize,
}

impl Condition {
    fn p50(&self) -> f64 {
        quantile(&self.voice_to_voice_ms, 0.5)
    }

    fn p95(&self) -> f64 {
        quantile(&self.voice_to_voice_ms, 0.95)
    }
}

/// Says `questions` (clip and its text) `runs` times in each condition.
pub async fn measure(
    watcher: &mut Watcher,
    say: &mpsc::Sender<Say>,
    questions: &Questions<'_>,
    runs: usize,
    page_url: &str,
    turn_pids: &[u32],
) -> anyhow::Result<Vec<Condition>> {
    let mut out = Vec::new();
    for name in ["quiet", "page", "busy", "busy_unit"] {
        if name == "busy_unit" && !renice(turn_pids, UNIT_NICE) {
            renice(turn_pids, -UNIT_NICE);
            println!(
                "  busy_unit skipped: this user may not raise priorities (the units' Nice=-5 needs systemd or root)"
            );
            continue;
        }
        let beside = Beside::start(name, page_url).await?;
        tokio::time::sleep(SETTLE).await;
        watcher.until_quiet(Duration::from_millis(800)).await?;
        out.push(ask(watcher, say, name, "rule", questions.rule, runs).await?);
        if !questions.model.is_empty() {
            out.push(
                ask(
                    watcher,
                    say,
                    name,
                    "model",
                    questions.model,
                    questions.model.len(),
                )
                .await?,
            );
        }
        beside.stop().await;
        if name == "busy_unit" {
            renice(turn_pids, -UNIT_NICE);
        }
    }
    Ok(out)
}

/// Says `runs` of `questions` (in turn) on `path` in condition `name`, following each to its reply.
async fn ask(
    watcher: &mut Watcher,
    say: &mpsc::Sender<Say>,
    name: &'static str,
    path: &'static str,
    questions: &[(Clip, &str)],
    runs: usize,
) -> anyhow::Result<Condition> {
    let mut c = Condition {
        name,
        path,
        ..Condition::default()
    };
    for run in 0..runs {
        let (clip, text) = &questions[run % questions.len()];
        let end = crate::speech_clip::say(say, clip).await?;
        let expected = words(text);
        c.words += expected.split(' ').count();
        let heard = if path == "model" {
            watcher
                .follow_chat(end, end + MODEL_PATIENCE)
                .await
                .map(|f| (f.voice_to_voice(), f.base.text))
        } else {
            watcher
                .follow(end, end + RULE_PATIENCE)
                .await
                .map(|f| (f.voice_to_voice(), f.text))
        };
        match heard {
            Ok((ms, text)) => {
                let said = words(&text);
                let said: Vec<&str> = said.split(' ').collect();
                let lost = expected.split(' ').filter(|w| !said.contains(w)).count();
                c.words_lost += lost;
                println!(
                    "  {name:<9} {path:<5} run {:>2} {ms:>6.0} ms  heard {text:?}{}",
                    run + 1,
                    if lost > 0 {
                        format!(" ({lost} words lost)")
                    } else {
                        String::new()
                    }
                );
                c.voice_to_voice_ms.push(ms);
            }
            Err(e) => {
                println!("  {name:<9} {path:<5} run {:>2} lost: {e:#}", run + 1);
                c.lost_runs += 1;
                c.words_lost += expected.split(' ').count();
            }
        }
        watcher.until_quiet(Duration::from_millis(800)).await?;
    }
    Ok(c)
}

/// The conditions' `SUMMARY` lines.
pub fn summary_lines(conditions: &[Condition]) -> Vec<String> {
    conditions
        .iter()
        .map(|c| {
            let quiet = conditions
                .iter()
                .find(|q| q.name == "quiet" && q.path == c.path)
                .map_or(f64::NAN, Condition::p50);
            let ratio = c.p50() / quiet;
            let target = match c.name {
                "page" => format!(
                    "; target <= {PAGE_TARGET}x quiet: {}",
                    if ratio <= PAGE_TARGET { "met" } else { "missed" }
                ),
                "busy" | "busy_unit" => format!(
                    "; target <= {BUSY_TARGET}x quiet: {}",
                    if ratio <= BUSY_TARGET { "met" } else { "missed" }
                ),
                _ => String::new(),
            };
            // The rule path keeps the names it had before the model's path was timed too.
            let path = if c.path == "model" { "model_" } else { "" };
            format!(
                "SUMMARY voice_to_voice_beside_{path}{}_p50: {:.0} ms (p95 {:.0} ms, ratio to quiet {ratio:.2}{target}; words lost {} of {}, runs lost {} of {})",
                c.name,
                c.p50(),
                c.p95(),
                c.words_lost,
                c.words,
                c.lost_runs,
                c.voice_to_voice_ms.len() + c.lost_runs
            )
        })
        .collect()
}
