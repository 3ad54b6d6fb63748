//! The Rust side, run as a child process of the bench (`llm-bench --serve`): llm-sat's llama.cpp engine loaded
//! once, answering the bench's requests (wire.rs) as llama_cpp_python_bench.py does, so that both sides are timed
//! the same way and each process's peak RSS is its own.

use std::io::{BufRead, Write};
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use anyhow::Context;
use llm_sat::engine::{Engine, EngineOptions};
use llm_sat::generator::{Flow, Generator, Limits, Message, Speaker};

use crate::wire::{ChatMessage, Finished, Ready, Reply, Request};

/// Tokens the context holds: llama-cpp-python's `n_ctx` in the baseline.
pub const CONTEXT: u32 = 2048;

/// How long one generation may take before the engine gives up: far beyond any run here.
const DEADLINE: Duration = Duration::from_secs(600);

/// Loads `model` and answers requests from stdin until it ends, then prints the process's peak RSS.
pub fn serve(model: &Path, threads: u32) -> anyhow::Result<()> {
    let started = Instant::now();
    let mut engine = Engine::load(
        model,
        EngineOptions {
            threads,
            context: CONTEXT,
            temperature: 0.0,
            seed: 0,
            min_tokens: 0,
        },
    )?;
    let mut out = std::io::stdout().lock();
    let ready = Ready {
        ready: true,
        load_s: started.elapsed().as_secs_f64(),
    };
    writeln!(out, "{}", serde_json::to_string(&ready)?)?;
    out.flush()?;
    for line in std::io::stdin().lock().lines() {
        let request: Request = serde_json::from_str(&line?).context("a request line")?;
        let reply = generate(&mut engine, &request)?;
        writeln!(out, "{}", serde_json::to_string(&reply)?)?;
        out.flush()?;
    }
    let finished = Finished {
        peak_rss_kb: peak_rss_kb()?,
    };
    writeln!(out, "{}", serde_json::to_string(&finished)?)?;
    Ok(())
}

fn generate(engine: &mut Engine, request: &Request) -> anyhow::Result<Reply> {
    let chat = request
        .messages
        .iter()
        .map(message)
        .collect::<anyhow::Result<Vec<_>>>()?;
    let cancel = AtomicBool::new(false);
    let mut first = None;
    let mut last = None;
    let mut text = String::new();
    let start = Instant::now();
    let generated = engine.generate(
        &chat,
        None,
        Limits {
            max_tokens: request.max_tokens,
            deadline: start + DEADLINE,
        },
        &cancel,
        &mut |piece| {
            let now = Instant::now();
            first.get_or_insert(now);
            last = Some(now);
            text.push_str(piece);
            Flow::Continue
        },
    )?;
    Ok(Reply {
        first_token_s: first.map(|f| (f - start).as_secs_f64()),
        decode_s: first.zip(last).map(|(f, l)| (l - f).as_secs_f64()),
        tokens: generated.tokens,
        prompt_tokens: Some(generated.prompt_tokens),
        cached_tokens: Some(generated.cached_tokens),
        ended: Some(format!("{:?}", generated.ended)),
        text,
    })
}

fn message(m: &ChatMessage) -> anyhow::Result<Message> {
    let speaker = match m.role.as_str() {
        "system" => Speaker::System,
        "user" => Speaker::User,
        "assistant" => Speaker::Assistant,
        other => anyhow::bail!("unknown role {other:?}"),
    };
    Ok(Message {
        speaker,
        content: m.content.clone(),
    })
}

/// This process's peak resident set (VmHWM), in KiB.
fn peak_rss_kb() -> anyhow::Result<u64> {
    let status = std::fs::read_to_string("/proc/self/status")?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .context("no VmHWM in /proc/self/status")
}
