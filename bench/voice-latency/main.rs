//! Voice-to-voice latency of the whole agent (`make bench`): from the end of the user's speech in the
//! `Agent.audio` stream to the first reply PCM on `Agent.speech`, with a real release `robot-agent` (brain and TTS
//! modules) and one real `whisper-sat` (tiny.en, 2 threads) on this machine.
//!
//! A microphone stand-in publishes real recorded utterances in real time, each followed by silence, and stamps
//! the wall time at which the chunk holding the last voiced sample went out. A watcher on the same hub stamps the
//! arrival of the `vad` end event and the final transcript (`Agent.transcript`), the rule trace the transcript
//! caused (`Agent.rules`) and the reply's first PCM frame (`Agent.speech`). The differences give the breakdown:
//! VAD hangover, ASR, rules, first TTS chunk; the hub hop is measured on its own. See docs/bench-voice-latency.md.
//!
//! A second phase, the chat phase, starts one release `llm-sat` (the default model) beside the satellite and says open
//! questions that the rules hand to the model with `chat(T)`: from the end of speech to the first PCM of the model's
//! spoken reply, with the model's `prompt` and first `sentence` events (`Agent.chat.reply`) in the breakdown.
//!
//! Options: `--runs N` (default 20), `--threads N` (satellite inference threads, default 2), `--hangover-ms N`
//! (default: the satellite's), `--satellite-arg ARG` (repeatable: passed on to `whisper-sat run`, to measure another
//! setting), `--chat-runs N` (open questions, default 20; 0 skips the chat phase), `--llm-threads N` (llm-sat's
//! generation threads, default 2), `--knowledge-runs N` (questions about the example knowledge folder, default 30, 0
//! skips; `knowledge.rs`), `--beside-runs N` (questions per condition of the beside phase, default 6; 0 skips
//! it), `--write PATH` (a Markdown report).
//!
//! The beside phase (`beside.rs`) says rule questions (and open ones for the model, with llm-sat) quiet, with the agent's page open in headless Chromium, beside
//! two busy loops, and beside them at the systemd units' priority, and reports each condition's voice to voice and
//! the words lost.

mod answer;
mod barge_in;
mod beside;
mod chat;
mod chat_report;
mod knowledge;
mod report;
mod rig;
mod speech_clip;
mod watch;

use agent_contract::channels as ch;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::Parser;
use flow::{Client, ConnectOptions, FlowAddr};
use tokio::sync::mpsc;

use crate::report::Figures;
use crate::rig::Rig;
use crate::speech_clip::{Clip, Ending};
use crate::watch::Watcher;

/// Whole turns, said in turn: two real recorded sentences from the shared fixtures (22050 Hz mono; JFK's last
/// phrase, from 8.0 s) and three questions and commands said by espeak-ng.
const FIXTURE_TURNS: [(&str, Option<f64>); 2] = [
    ("audio/LJ001-0002.wav", None),
    ("audio/derived/jfk_22050.wav", Some(8.0)),
];
const SPOKEN_TURNS: [&str; 3] = [
    "What time is it?",
    "Turn left.",
    "How many people do you see?",
];
/// Every this many runs one is a phrase cut inside a longer recorded sentence, at the pause after it (the
/// satellite's segmentation splits those sentences there): the speaker is not done, and the agent should wait.
const MID_SENTENCE_EVERY: usize = 6;
const MID_SENTENCE: [(&str, f64); 2] = [
    ("audio/LJ001-0004.wav", 1.65),
    ("audio/LJ001-0001.wav", 4.2),
];
/// How long one run may take from the end of speech to the reply before it counts as lost.
const RUN_PATIENCE: Duration = Duration::from_secs(60);

/// Voice-to-voice latency of the whole agent: end of the user's speech to the first reply PCM, with a release
/// `robot-agent`, `whisper-sat` and (the chat phase) `llm-sat`.
#[derive(Debug, clap::Parser)]
struct Options {
    /// Turns said and timed (at least 1).
    #[arg(long, default_value_t = 20)]
    runs: usize,
    /// The satellite's inference threads.
    #[arg(long, default_value_t = 2)]
    threads: u32,
    /// The satellite's end-of-speech hangover (ms) [default: the satellite's].
    #[arg(long)]
    hangover_ms: Option<u32>,
    /// Passed on to `whisper-sat run`, to measure another setting (repeatable; `--satellite-arg
    /// --turn-confirm-ms=150`).
    #[arg(long = "satellite-arg", value_name = "ARG", allow_hyphen_values = true)]
    satellite_args: Vec<String>,
    /// Write a Markdown report here.
    #[arg(long, value_name = "PATH")]
    write: Option<PathBuf>,
    /// Barge-ins: the user talking over the agent's reply.
    #[arg(long, default_value_t = 8)]
    barge_ins: usize,
    /// Open questions the rules hand to the language model (0 skips the chat phase).
    #[arg(long, default_value_t = chat::QUESTIONS.len())]
    chat_runs: usize,
    /// llm-sat's generation threads.
    #[arg(long, default_value_t = 2)]
    llm_threads: u32,
    /// Questions about the example knowledge folder typed to the agent with llm-sat beside it (at most the 30 of
    /// bench/knowledge/questions.toml; 0 skips the knowledge phase, which needs the chat phase's llm-sat).
    #[arg(long, default_value_t = 30)]
    knowledge_runs: usize,
    /// Rule questions per condition of the beside phase: quiet, the page open, two busy loops (0 skips it).
    #[arg(long, default_value_t = 6)]
    beside_runs: usize,
}

fn options() -> anyhow::Result<Options> {
    let o = Options::parse();
    if o.runs == 0 {
        bail!("--runs must be at least 1");
    }
    Ok(o)
}

/// `$AGENT_FIXTURES`, else `shared/fixtures` beside the repository.
fn fixtures() -> PathBuf {
    std::env::var_os("AGENT_FIXTURES").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/fixtures"),
        PathBuf::from,
    )
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let opts = options()?;
    let mut turns: Vec<Clip> = FIXTURE_TURNS
        .iter()
        .map(|(path, start)| Clip::load(&fixtures().join(path), *start, None, Ending::Turn))
        .collect::<anyhow::Result<_>>()
        .context(
            "loading the fixture clips (set AGENT_FIXTURES to the shared fixtures directory)",
        )?;
    let scratch = tempfile::tempdir()?;
    for text in SPOKEN_TURNS {
        turns.push(Clip::espeak(text, scratch.path())?);
    }
    let mid_sentence: Vec<Clip> = MID_SENTENCE
        .iter()
        .map(|(path, cut)| {
            Clip::load(
                &fixtures().join(path),
                None,
                Some(*cut),
                Ending::MidSentence,
            )
        })
        .collect::<anyhow::Result<_>>()?;
    let clips: Vec<&Clip> = turns.iter().chain(&mid_sentence).collect();
    let bins = rig::bin_dir()?;
    println!(
        "voice-to-voice latency: {} runs, whisper-sat tiny.en with {} threads, binaries from {}",
        opts.runs,
        opts.threads,
        bins.display()
    );
    for c in &clips {
        println!(
            "  clip {} ({}): {:.2} s, speech ends at {:.2} s",
            c.name,
            c.ending.label(),
            c.seconds(),
            c.voiced_end as f64 / f64::from(speech_clip::RATE)
        );
    }

    let mut rig = Rig::start(&bins).await?;
    let addr: FlowAddr = rig
        .flow_tcp
        .parse()
        .map_err(anyhow::Error::msg)
        .context("the server's TCP address")?;
    let connect = |name: &str| {
        let mut o = ConnectOptions::new(name, rig.token.clone());
        o.reconnect = false;
        // Reply speech arrives paced but in bursts of 300 ms; nothing here may be dropped.
        o.queue = 4096;
        o
    };
    let watcher_client = Client::connect(&addr, connect("bench-watch")).await?;
    let mic_client = Client::connect(&addr, connect("bench-mic")).await?;
    let hop = watch::hub_hop(&mic_client, &watcher_client, 250).await?;
    let mut watcher = Watcher::start(&watcher_client).await?;

    rig.start_satellite(&bins, opts.threads, opts.hangover_ms, &opts.satellite_args)
        .await?;
    watch::wait_channel(
        &watcher_client,
        &format!("{}bench-asr", ch::ASR_PRESENCE_PREFIX),
        Duration::from_secs(120),
    )
    .await
    .context("the satellite did not join (is the model there? `make model`)")?;
    let publisher = mic_client
        .publisher(
            ch::AUDIO.name,
            r#"{"mime":"audio/pcm","rate":22050,"channels":1,"format":"s16le"}"#,
        )
        .await?;
    let (say_tx, say_rx) = mpsc::channel(1);
    let mic = tokio::spawn(speech_clip::microphone(publisher, say_rx));
    // Silence first, so the satellite's stream is running before the first utterance.
    tokio::time::sleep(Duration::from_secs(2)).await;

    let mut figures = Figures::default();
    let load_before = report::load_average();
    let (mut next_turn, mut next_mid) = (0, 0);
    for run in 0..opts.runs {
        let clip = if (run + 1) % MID_SENTENCE_EVERY == 0 {
            next_mid += 1;
            &mid_sentence[(next_mid - 1) % mid_sentence.len()]
        } else {
            next_turn += 1;
            &turns[(next_turn - 1) % turns.len()]
        };
        let end_of_speech = crate::speech_clip::say(&say_tx, clip).await?;
        match watcher
            .follow(end_of_speech, end_of_speech + RUN_PATIENCE)
            .await
        {
            Ok(mut run_figures) => {
                run_figures.ending = clip.ending;
                println!(
                    "  run {:>2} {:<12} {}",
                    run + 1,
                    clip.name,
                    run_figures.line()
                );
                figures.runs.push(run_figures);
            }
            Err(e) => {
                println!("  run {:>2} {:<12} lost: {e:#}", run + 1, clip.name);
                figures.lost += 1;
            }
        }
        // Let the reply play out, so the next utterance does not barge in on it.
        watcher.until_quiet(Duration::from_millis(800)).await?;
    }
    if opts.barge_ins > 0 {
        println!(
            "barge-in: {} runs, talking over a long reply, each followed by a 150 ms burst",
            opts.barge_ins
        );
        let hm = Clip::espeak("hm", scratch.path())?;
        let burst = Clip::burst(&hm, 150);
        let rig = barge_in::Rig::start(&watcher_client, &say_tx).await?;
        let talkers: Vec<&Clip> = turns.iter().collect();
        figures.barge_ins = barge_in::measure(&rig, &talkers, &burst, opts.barge_ins).await?;
    }
    figures.load = (load_before, report::load_average());
    // llm-sat joins before the beside phase, which times the model's path too, and stays for the chat phase.
    let llm_pid = if opts.chat_runs > 0 {
        let pid = rig.start_llm_sat(&bins, opts.llm_threads)?;
        watch::wait_channel(&watcher_client, ch::CHAT.name, Duration::from_secs(120))
            .await
            .context("llm-sat did not join (is the model there? `make model-llm`)")?;
        // What the watcher queued during the barge-ins is not a question's.
        watcher.until_quiet(Duration::from_millis(800)).await?;
        Some(pid)
    } else {
        None
    };
    let beside_figures = if opts.beside_runs > 0 {
        println!(
            "beside: {} rule questions each quiet, with the page open in headless Chromium, and beside two busy loops",
            opts.beside_runs
        );
        let questions: Vec<(Clip, &str)> = SPOKEN_TURNS
            .iter()
            .map(|text| Ok((Clip::espeak(text, scratch.path())?, *text)))
            .collect::<anyhow::Result<_>>()?;
        // The model's path: as many open questions per condition, when llm-sat is there.
        let open: Vec<(Clip, &str)> = if llm_pid.is_some() {
            chat::QUESTIONS
                .iter()
                .take(opts.beside_runs)
                .map(|text| Ok((Clip::espeak(text, scratch.path())?, *text)))
                .collect::<anyhow::Result<_>>()?
        } else {
            Vec::new()
        };
        let pids = rig.turn_pids();
        beside::measure(
            &mut watcher,
            &say_tx,
            &beside::Questions {
                rule: &questions,
                model: &open,
            },
            opts.beside_runs,
            &rig.page_url,
            &pids,
        )
        .await?
    } else {
        Vec::new()
    };
    let chat_figures = if let Some(llm_pid) = llm_pid {
        println!(
            "chat: {} open questions answered by llm-sat (default model, {} threads) beside whisper-sat",
            opts.chat_runs, opts.llm_threads
        );
        Some(
            chat::measure(
                &mut watcher,
                &say_tx,
                opts.chat_runs,
                llm_pid,
                scratch.path(),
            )
            .await?,
        )
    } else {
        None
    };
    let knowledge_figures = if llm_pid.is_some() && opts.knowledge_runs > 0 {
        let sets = agent_bench::knowledge_set::load(&agent_bench::knowledge_set::default_path())?;
        let questions = &sets.on_topic[..opts.knowledge_runs.min(sets.on_topic.len())];
        println!(
            "knowledge: {} questions about the example folder, typed as final transcripts",
            questions.len()
        );
        // whisper-sat owns Agent.transcript: it goes, and its channel with it, before the questions are typed.
        rig.stop_satellite().await?;
        let gone = tokio::time::timeout(Duration::from_secs(30), async {
            while mic_client.channel(ch::TRANSCRIPT.name).await.is_ok() {
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        })
        .await;
        gone.context("Agent.transcript stayed after whisper-sat stopped")?;
        let transcript = mic_client
            .publisher(ch::TRANSCRIPT.name, ch::headers::TRANSCRIPT)
            .await?;
        Some(knowledge::measure(&mut watcher, &transcript, questions).await?)
    } else {
        None
    };
    drop(say_tx);
    mic.await.context("the microphone task")??;
    figures.hop = hop;
    figures.print(&opts_summary(&opts));
    for line in beside::summary_lines(&beside_figures) {
        println!("{line}");
    }
    let chat_setup = format!(
        "{} open questions, llm-sat SmolLM2-135M-Instruct Q4_1 with {} threads beside whisper-sat with {}",
        opts.chat_runs, opts.llm_threads, opts.threads
    );
    if let Some(chat) = &chat_figures {
        chat.print(&chat_setup);
    }
    if let Some(knowledge) = &knowledge_figures {
        knowledge.print();
    }
    if let Some(path) = &opts.write {
        let mut markdown = figures.markdown(&opts_summary(&opts));
        if let Some(chat) = &chat_figures {
            markdown.push('\n');
            markdown.push_str(&chat.markdown(&chat_setup));
        }
        if let Some(knowledge) = &knowledge_figures {
            markdown.push('\n');
            markdown.push_str(&knowledge.markdown());
        }
        report::write_figures(path, &markdown)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn opts_summary(o: &Options) -> String {
    format!(
        "{} runs, tiny.en, {} inference threads, hangover {}",
        o.runs,
        o.threads,
        o.hangover_ms
            .map_or_else(|| "default".to_owned(), |ms| format!("{ms} ms"))
    ) + &if o.satellite_args.is_empty() {
        String::new()
    } else {
        format!(", satellite {}", o.satellite_args.join(" "))
    }
}
