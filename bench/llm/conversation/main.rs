//! `llm-conversation`: llm-sat's model on a written set of conversational questions (bench/llm/conversation.toml:
//! greetings, follow-ups that need the memory, arithmetic, small talk, what the agent sees, passages of the
//! knowledge folder), each reply scored against the set's rubric; and the latency of a turn: prompt tokens, how
//! many of them the cache held, time to the first token and to the first spoken chunk (issue 49).
//!
//! Every turn goes through llm-sat's own path (`llm_sat::turn::run`: the prompt, the engine, the spoken splitter)
//! with the satellite's default limits, and its reply joins the next turn's history as the brain keeps it (the
//! question with its facts, the reply as generated), trimmed by half when `--memory` turns are exceeded.
//!
//! - default: the set, scored (`SUMMARY llm_conversation_score`);
//! - `--latency`: 20 open questions in one conversation (voice-latency's chat phase's), the clock moving a minute
//!   every other question: medians of new prompt tokens, first token and first chunk;
//! - `--sweep`: prompt reading and decoding speed against the context length (docs/llm.md's table).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use agent_bench::percentile;
use agent_contract::chat::{ChatMessage, ChatRequest, Facts, Passage, Role};
use anyhow::Context;
use clap::Parser;
use llm_sat::engine::{Engine, EngineOptions};
use llm_sat::generator::{Flow, Generator, Limits, Message, Speaker};
use llm_sat::prompt::Renderings;
use llm_sat::turn::{self, Step, TurnLimits};
use serde::Deserialize;

#[derive(Debug, Parser)]
#[command(
    about = "llm-sat's model on a conversational set, scored; turn latency; speed against context length"
)]
struct Args {
    #[arg(long, default_value = "models/llm/SmolLM2-135M-Instruct.Q4_1.gguf")]
    model: PathBuf,
    #[arg(long, default_value = "bench/llm/conversation.toml")]
    set: PathBuf,
    #[arg(long, default_value_t = 2)]
    threads: u32,
    /// The satellite's `--context`.
    #[arg(long, default_value_t = 2048)]
    context: u32,
    /// The satellite's `--temperature` (0: greedy).
    #[arg(long, default_value_t = 0.0)]
    temperature: f32,
    /// The brain's `chat_memory_turns` (config/default.toml).
    #[arg(long, default_value_t = 4)]
    memory: usize,
    /// Run the 20 open questions in one conversation and report the latency of each turn.
    #[arg(long)]
    latency: bool,
    /// Measure prompt reading and decoding speed against the context length.
    #[arg(long)]
    sweep: bool,
    /// Print each turn's prompt as the model sees it.
    #[arg(long)]
    show_prompt: bool,
}

/// The set: the rubric's shared forbidden texts, the default facts, the conversations.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Set {
    #[serde(default)]
    forbid: Vec<String>,
    /// The latency run's questions: voice-latency's chat phase's.
    #[serde(default)]
    open_questions: Vec<String>,
    facts: SetFacts,
    conversation: Vec<Conversation>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SetFacts {
    time: String,
    date: String,
    faces: u32,
    face_where: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Conversation {
    name: String,
    faces: Option<u32>,
    face_where: Option<String>,
    code: Option<String>,
    #[serde(default)]
    passage: Vec<Passage>,
    turn: Vec<Turn>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Turn {
    ask: String,
    faces: Option<u32>,
    time: Option<String>,
    #[serde(default)]
    any: Vec<String>,
    #[serde(default)]
    forbid: Vec<String>,
    #[serde(default)]
    echo: bool,
}

/// The satellite's default limits (llm-sat's flags).
const LIMITS: TurnLimits = TurnLimits {
    max_sentences: 3,
    max_tokens: 160,
    timeout: Duration::from_secs(15),
    offer_tools: false,
};

/// What one turn did.
struct Done {
    reply: String,
    generated: String,
    prompt_tokens: u32,
    cached_tokens: u32,
    first_token_ms: u64,
    first_chunk_ms: Option<u64>,
    first_chunk: Option<String>,
}

/// A conversation as the brain keeps it.
struct Memory {
    lines: Vec<ChatMessage>,
    turns: usize,
    /// How llm-sat rendered each question, as its generator thread keeps it.
    renderings: Renderings,
}

impl Memory {
    fn keep(&mut self, question: &str, facts: Facts, done: &Done) {
        self.lines.push(ChatMessage {
            role: Role::User,
            text: question.to_owned(),
            interrupted: false,
            facts: Some(facts),
            generated: None,
        });
        self.lines.push(ChatMessage {
            role: Role::Assistant,
            text: done.reply.clone(),
            interrupted: false,
            facts: None,
            generated: Some(done.generated.clone()),
        });
        // As agent/server's brain/chat.rs trims it: by half when full.
        let keep = self.turns * 2;
        if self.lines.len() > keep {
            let half = (keep / 2).max(2);
            self.lines.drain(..self.lines.len() - half);
        }
    }
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    anyhow::ensure!(
        args.model.is_file(),
        "{}: no model file (`make model-llm` provisions it)",
        args.model.display()
    );
    let mut engine = Engine::load(
        &args.model,
        EngineOptions {
            threads: args.threads,
            context: args.context,
            temperature: args.temperature,
            seed: 1,
            min_tokens: 0,
        },
    )?;
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "llm-conversation: {} with {} threads, memory {} turns; load average at start: {}",
        args.model.display(),
        args.threads,
        args.memory,
        load.split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
            .join(" ")
    );
    if args.sweep {
        return sweep(&mut engine);
    }
    let text = std::fs::read_to_string(&args.set)
        .with_context(|| format!("{}: cannot read the set", args.set.display()))?;
    let set: Set =
        toml::from_str(&text).with_context(|| format!("{}: not a set", args.set.display()))?;
    if args.latency {
        return latency(&mut engine, &set, &args);
    }
    score(&mut engine, &set, &args)
}

/// The set's facts for a conversation's turn.
fn facts_of(set: &Set, conversation: &Conversation, turn: &Turn) -> Facts {
    Facts {
        faces: turn.faces.or(conversation.faces).unwrap_or(set.facts.faces),
        face_where: conversation
            .face_where
            .clone()
            .or_else(|| set.facts.face_where.clone())
            .filter(|_| turn.faces != Some(0)),
        speaker_where: None,
        names: Vec::new(),
        code: conversation.code.clone(),
        motion: None,
        time: turn.time.clone().unwrap_or_else(|| set.facts.time.clone()),
        date: set.facts.date.clone(),
        last_said: None,
        passages: conversation.passage.clone(),
    }
}

fn score(engine: &mut Engine, set: &Set, args: &Args) -> anyhow::Result<()> {
    let (mut passed, mut total) = (0, 0);
    let mut first_tokens = Vec::new();
    let mut first_chunks = Vec::new();
    let mut new_tokens = Vec::new();
    for conversation in &set.conversation {
        println!("## {}", conversation.name);
        let mut memory = Memory {
            lines: Vec::new(),
            turns: args.memory,
            renderings: Renderings::default(),
        };
        let mut previous: Option<String> = None;
        for turn in &conversation.turn {
            let facts = facts_of(set, conversation, turn);
            let done = ask(
                engine,
                &mut memory,
                &turn.ask,
                facts.clone(),
                args.show_prompt,
            )?;
            let verdict = judge(set, turn, &done.reply, previous.as_deref());
            total += 1;
            if verdict.is_ok() {
                passed += 1;
            }
            first_tokens.push(done.first_token_ms as f64);
            if let Some(ms) = done.first_chunk_ms {
                first_chunks.push(ms as f64);
            }
            new_tokens.push(f64::from(done.prompt_tokens - done.cached_tokens));
            println!(
                "  [{}] {:?} -> {:?}{}",
                match &verdict {
                    Ok(()) => "ok".to_owned(),
                    Err(why) => format!("MISS: {why}"),
                },
                turn.ask,
                done.reply,
                chunk_note(&done)
            );
            memory.keep(&turn.ask, facts, &done);
            previous = Some(done.reply);
        }
    }
    println!(
        "SUMMARY llm_conversation_score: {passed}/{total} turns on the question ({:.0}%)",
        100.0 * f64::from(passed) / f64::from(total.max(1))
    );
    print_medians(&new_tokens, &first_tokens, &first_chunks);
    Ok(())
}

fn chunk_note(done: &Done) -> String {
    format!(
        " (prompt {} tokens, {} cached; first token {} ms, first chunk {} ms: {:?})",
        done.prompt_tokens,
        done.cached_tokens,
        done.first_token_ms,
        done.first_chunk_ms
            .map_or_else(|| "-".to_owned(), |ms| ms.to_string()),
        done.first_chunk.as_deref().unwrap_or("")
    )
}

fn print_medians(new_tokens: &[f64], first_tokens: &[f64], first_chunks: &[f64]) {
    println!(
        "SUMMARY llm_conversation_new_prompt_tokens_p50: {:.0} (p95 {:.0})",
        percentile(new_tokens, 0.5),
        percentile(new_tokens, 0.95)
    );
    println!(
        "SUMMARY llm_conversation_first_token_p50: {:.0} ms (p95 {:.0} ms)",
        percentile(first_tokens, 0.5),
        percentile(first_tokens, 0.95)
    );
    println!(
        "SUMMARY llm_conversation_first_chunk_p50: {:.0} ms (p95 {:.0} ms)",
        percentile(first_chunks, 0.5),
        percentile(first_chunks, 0.95)
    );
}

/// The rubric for one reply.
fn judge(set: &Set, turn: &Turn, reply: &str, previous: Option<&str>) -> Result<(), String> {
    let lower = reply.to_lowercase();
    if lower.trim().is_empty() {
        return Err("no reply".into());
    }
    if !turn.any.is_empty() && !turn.any.iter().any(|a| lower.contains(&a.to_lowercase())) {
        return Err(format!("none of {:?}", turn.any));
    }
    if let Some(bad) = set
        .forbid
        .iter()
        .chain(&turn.forbid)
        .find(|f| lower.contains(&f.to_lowercase()))
    {
        return Err(format!("holds {bad:?}"));
    }
    if turn.echo {
        let before: Vec<String> = previous
            .unwrap_or_default()
            .split(|c: char| !c.is_alphanumeric())
            .filter(|w| w.len() >= 4)
            .map(str::to_lowercase)
            .collect();
        let found = before.iter().filter(|w| lower.contains(w.as_str())).count();
        if before.is_empty() || found * 2 < before.len() {
            return Err(format!("{found} of {} earlier words", before.len()));
        }
    }
    Ok(())
}

/// One turn through llm-sat's own path.
fn ask(
    engine: &mut Engine,
    memory: &mut Memory,
    question: &str,
    facts: Facts,
    show_prompt: bool,
) -> anyhow::Result<Done> {
    let request = ChatRequest {
        turn: 1,
        text: question.to_owned(),
        language: "en".into(),
        facts,
        history: memory.lines.clone(),
        tools: Vec::new(),
        force_tool: None,
        speculative: false,
        max_sentences: None,
        timeout_ms: None,
        trace: None,
    };
    let cancel = AtomicBool::new(false);
    let started = Instant::now();
    let mut first_chunk = None;
    let outcome = turn::run(
        engine,
        &mut memory.renderings,
        &request,
        LIMITS,
        &cancel,
        &mut |step| match step {
            Step::Prompt(prompt) if show_prompt => println!("{prompt}"),
            Step::Sentence(text) if first_chunk.is_none() => {
                first_chunk = Some((started.elapsed().as_millis() as u64, text));
            }
            _ => {}
        },
    )?;
    Ok(Done {
        reply: outcome.sentences.join(" "),
        generated: outcome.generated,
        prompt_tokens: outcome.stats.prompt_tokens,
        cached_tokens: outcome.stats.cached_tokens,
        first_token_ms: outcome.stats.first_token_ms,
        first_chunk_ms: first_chunk.as_ref().map(|(ms, _)| *ms),
        first_chunk: first_chunk.map(|(_, text)| text),
    })
}

/// The set's open questions (the chat phase's 20) in one conversation, the clock moving a minute every other question.
fn latency(engine: &mut Engine, set: &Set, args: &Args) -> anyhow::Result<()> {
    let mut memory = Memory {
        lines: Vec::new(),
        turns: args.memory,
        renderings: Renderings::default(),
    };
    let (mut new_tokens, mut first_tokens, mut first_chunks) = (Vec::new(), Vec::new(), Vec::new());
    let mut prompts = Vec::new();
    for (n, question) in set.open_questions.iter().enumerate() {
        let facts = Facts {
            faces: 1,
            face_where: Some("centre".into()),
            time: format!("{} past four in the afternoon", 10 + n / 2),
            date: "Saturday 5 December".into(),
            ..Facts::default()
        };
        let done = ask(
            engine,
            &mut memory,
            question,
            facts.clone(),
            args.show_prompt,
        )?;
        println!(
            "  {:>2} {question:?} -> {:?}{}",
            n + 1,
            done.reply,
            chunk_note(&done)
        );
        new_tokens.push(f64::from(done.prompt_tokens - done.cached_tokens));
        prompts.push(f64::from(done.prompt_tokens));
        first_tokens.push(done.first_token_ms as f64);
        if let Some(ms) = done.first_chunk_ms {
            first_chunks.push(ms as f64);
        }
        memory.keep(question, facts, &done);
    }
    println!(
        "SUMMARY llm_conversation_prompt_tokens_p50: {:.0} (p95 {:.0})",
        percentile(&prompts, 0.5),
        percentile(&prompts, 0.95)
    );
    print_medians(&new_tokens, &first_tokens, &first_chunks);
    Ok(())
}

/// Words of filler for the sweep's context: a conversation that grows to the length asked for.
const FILLER: &str = "The museum opened its doors to a class of thirty children and their two teachers, who had \
travelled by train from a village in the hills. In the first hall they found a steam engine that still worked, \
and a guide showed them how the pistons moved. ";

/// How fast the model reads a prompt and writes a reply as the context fills: for each context length, 64 new
/// prompt tokens read after a cached context of that length (ms per token), and the decode rate there.
fn sweep(engine: &mut Engine) -> anyhow::Result<()> {
    println!(
        "| context (tokens) | new prompt tokens | reading (ms/token) | first token (ms) | decode (tokens/s) |"
    );
    println!("|---|---|---|---|---|");
    let cancel = AtomicBool::new(false);
    for (round, words) in [0usize, 150, 300, 450, 600, 750, 900, 1200]
        .into_iter()
        .enumerate()
    {
        let mut readings = Vec::new();
        let mut decodes = Vec::new();
        let mut firsts = Vec::new();
        let mut context = 0;
        let mut fresh = 0;
        for run in 0..3 {
            let mut chat = vec![Message {
                speaker: Speaker::System,
                content: format!("Conversation {round}. You are a friendly robot. Answer briefly."),
            }];
            let filler: String = FILLER
                .split_whitespace()
                .cycle()
                .take(words)
                .collect::<Vec<_>>()
                .join(" ");
            if words > 0 {
                chat.push(Message {
                    speaker: Speaker::User,
                    content: filler,
                });
                chat.push(Message {
                    speaker: Speaker::Assistant,
                    content: "I see.".into(),
                });
            }
            // The cached context, read untimed.
            let limits = Limits {
                max_tokens: 1,
                deadline: Instant::now() + Duration::from_secs(600),
            };
            engine.generate(&chat, None, limits, &cancel, &mut |_| Flow::Continue)?;
            // 64 new tokens or so: about what a turn reads.
            chat.push(Message {
                speaker: Speaker::User,
                content: format!(
                    "Question {run}: please tell me, in many words and with every detail you remember, the whole \
                     story of the children at the museum, from the train in the morning to the drawings on the \
                     board in the evening, and what the guide said."
                ),
            });
            let started = Instant::now();
            let (mut first, mut last) = (None, None);
            let generated = engine.generate(
                &chat,
                None,
                Limits {
                    max_tokens: 48,
                    deadline: started + Duration::from_secs(600),
                },
                &cancel,
                &mut |_| {
                    let now = Instant::now();
                    first.get_or_insert(now);
                    last = Some(now);
                    Flow::Continue
                },
            )?;
            let (Some(first), Some(last)) = (first, last) else {
                continue;
            };
            fresh = generated.prompt_tokens - generated.cached_tokens;
            context = generated.cached_tokens;
            let first_ms = (first - started).as_secs_f64() * 1000.0;
            firsts.push(first_ms);
            readings.push(first_ms / f64::from(fresh.max(1)));
            if generated.tokens > 1 {
                decodes.push(f64::from(generated.tokens - 1) / (last - first).as_secs_f64());
            }
        }
        println!(
            "| {context} | {fresh} | {:.2} | {:.0} | {:.0} |",
            percentile(&readings, 0.5),
            percentile(&firsts, 0.5),
            percentile(&decodes, 0.5)
        );
    }
    Ok(())
}
