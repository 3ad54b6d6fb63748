//! The chat phase: open questions said by espeak-ng, which no rule of the shipped program answers, so that the
//! catch-all rule hands each to `llm-sat` with `chat(T)`; one question at a time, each measured from the end of its
//! speech to the first PCM of the model's spoken reply, the next said once the reply has ended and played out.

use std::path::Path;
use std::time::{Duration, Instant};

use tokio::sync::mpsc;

use crate::chat_report::{ChatFigures, peak_rss_kb};
use crate::speech_clip::{Clip, Say};
use crate::watch::Watcher;

/// Twenty open questions. Each was checked against the patterns of config/brain.tr: no time, date, counting,
/// seeing, code, repeat, greeting, thanks, name, uptime, machine, turning, forgetting or stop phrase, so each goes
/// to `answer.confused`, which calls `chat(T)`. They are ones tiny.en hears right (or nearly) as espeak-ng says
/// them: "Why do cats like boxes?" came out as "Wydu Cat's Psych boxes", which the model only echoes.
pub const QUESTIONS: [&str; 20] = [
    "Why is the sky blue?",
    "What is your favourite colour?",
    "Why do leaves change colour in autumn?",
    "How does a rainbow form?",
    "Why do we need sleep?",
    "Why is the moon so bright?",
    "What should I cook for dinner?",
    "How far away is the sun?",
    "What is a good game to play?",
    "Why do people laugh?",
    "Why do we dream?",
    "What is the best way to learn a language?",
    "What is gravity?",
    "How do computers work?",
    "What is the tallest mountain in the world?",
    "What is a black hole?",
    "What is your favourite food?",
    "Why is the ocean so deep?",
    "What makes the ocean salty?",
    "What is the capital of France?",
];

/// A reply of three sentences, generated and spoken, fits well within this.
const RUN_PATIENCE: Duration = Duration::from_secs(90);

/// Says `runs` questions (in turn, from the first) and follows each to the end of the model's reply. `llm_pid` is
/// read for the satellite's peak memory at the end.
pub async fn measure(
    watcher: &mut Watcher,
    say: &mpsc::Sender<Say>,
    runs: usize,
    llm_pid: u32,
    scratch: &Path,
) -> anyhow::Result<ChatFigures> {
    let clips: Vec<Clip> = QUESTIONS
        .iter()
        .map(|q| Clip::espeak(q, scratch))
        .collect::<anyhow::Result<_>>()?;
    let mut figures = ChatFigures::default();
    for run in 0..runs {
        let clip = &clips[run % clips.len()];
        let end_of_speech = crate::speech_clip::say(say, clip).await?;
        match watcher
            .follow_chat(end_of_speech, Instant::now() + RUN_PATIENCE)
            .await
        {
            Ok(run_figures) => {
                println!("  chat {:>2} {}", run + 1, run_figures.line());
                figures.runs.push(run_figures);
            }
            Err(e) => {
                println!("  chat {:>2} {:?} lost: {e:#}", run + 1, clip.name);
                figures.lost += 1;
            }
        }
        // Let the rest of the reply play out, so the next question does not barge in on it.
        watcher.until_quiet(Duration::from_millis(800)).await?;
    }
    figures.peak_rss_kb = peak_rss_kb(llm_pid);
    Ok(figures)
}
