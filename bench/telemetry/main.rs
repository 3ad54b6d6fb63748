//! What tracing costs a turn (`make bench`; docs/telemetry.md, "Cost"): the spans robot-agent, whisper-sat and
//! llm-sat record for one spoken turn (the turn, its four stages, the synthesis, a decode, the generation, its first
//! token and three sentences), recorded through `flow_telemetry::Telemetry` as those processes do, turn after turn,
//! with telemetry off and then on, exporting over OTLP/HTTP to a collector in this process that decodes every export
//! with OpenTelemetry's protobuf definitions. CPU time is read per thread (the recording thread, and the batch
//! processor's and HTTP client's threads that telemetry adds), so the collector's own work is not counted.
//!
//! Options: `--turns N` (default 2000).

use std::collections::HashMap;
use std::time::{Duration, Instant};

use agent_tests::otlp::Collector;
use anyhow::Context;
use clap::Parser;
use flow_telemetry::{SpanRecord, Telemetry, TraceContext};

/// Spans one turn records with a chat reply of three sentences.
const SPANS_PER_TURN: usize = 12;
/// The turn the share is taken of: about what the rule path takes from end of speech to reply (docs/benchmarks.md).
const TURN_MS: f64 = 200.0;

/// What tracing costs a turn, off and on.
#[derive(Debug, clap::Parser)]
struct Options {
    /// Turns recorded in each phase.
    #[arg(long, default_value_t = 2000)]
    turns: usize,
}

/// The spans of turn `n`, as the three processes record them (times on the Unix clock, µs).
fn record_turn(telemetry: &Telemetry, n: usize) {
    // The processes check before they build anything.
    if !telemetry.is_on() {
        return;
    }
    let turn = TraceContext::turn(&format!("u{}", 1_765_000_000_000u64 + n as u64));
    let t0 = flow_telemetry::now_us();
    telemetry.record(
        SpanRecord::root("turn", turn, t0, t0 + 900_000)
            .with("utterance", format!("u{n}"))
            .with("rule", "main.converse > answer.confused"),
    );
    let mut at = t0;
    for (stage, us) in [
        ("voice_activity", 300_000),
        ("transcription", 150_000),
        ("rule", 2_000),
        ("reply", 448_000),
    ] {
        telemetry.record(SpanRecord::under(turn, stage, at, at + us));
        at += us;
    }
    telemetry.record(
        SpanRecord::under_as(
            turn.child("transcription"),
            "whisper.decode",
            "decode whisper-1",
            t0 + 250_000,
            t0 + 450_000,
        )
        .with("satellite", "whisper-1")
        .with("model", "tiny.en")
        .with("audio_ms", 1800u64)
        .with("speculative", true),
    );
    let reply = turn.child("reply");
    let generate = SpanRecord::under(reply, "llm.generate", t0 + 452_000, t0 + 1_400_000)
        .with("satellite", "llm-1")
        .with("model", "SmolLM2-135M-Instruct.Q4_1")
        .with("tokens", 47u32)
        .with("prompt_tokens", 610u32)
        .with("cached_tokens", 540u32);
    let generation = generate.context;
    telemetry.record(generate);
    telemetry.record(SpanRecord::under(
        generation,
        "llm.first_token",
        t0 + 452_000,
        t0 + 700_000,
    ));
    for i in 0..3u64 {
        let from = t0 + 700_000 + i * 200_000;
        telemetry.record(
            SpanRecord::under_as(
                generation,
                "llm.sentence",
                &format!("sentence {i}"),
                from,
                from + 200_000,
            )
            .with("index", i),
        );
    }
    telemetry.record(
        SpanRecord::under(reply, "synthesis", t0 + 880_000, t0 + 900_000).with("utterance", 7u64),
    );
}

/// CPU time (ns) of this process's threads by name, from /proc.
fn thread_cpu() -> HashMap<String, u64> {
    let mut by_name = HashMap::new();
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return by_name;
    };
    for task in tasks.flatten() {
        let name = std::fs::read_to_string(task.path().join("comm")).unwrap_or_default();
        let ns = std::fs::read_to_string(task.path().join("schedstat"))
            .ok()
            .and_then(|s| {
                s.split_whitespace()
                    .next()
                    .and_then(|v| v.parse::<u64>().ok())
            })
            .unwrap_or(0);
        *by_name.entry(name.trim().to_owned()).or_insert(0) += ns;
    }
    by_name
}

/// CPU of the threads telemetry starts (all but the runtime's and the collector's, which existed before it).
fn added_cpu(before: &HashMap<String, u64>, after: &HashMap<String, u64>) -> u64 {
    after
        .iter()
        .filter(|(name, _)| !before.contains_key(*name))
        .map(|(_, ns)| ns)
        .sum()
}

/// Turns recorded between two flushes: 1200 spans, within the batch processor's queue of 2048 (turns come seconds
/// apart in use; a burst past the queue would drop spans, as the processor's overflow policy says).
const TURNS_PER_FLUSH: usize = 100;

/// Records `turns` turns on this thread and returns its CPU time per turn (ns); waiting for a flush costs no CPU.
fn recording_cost(telemetry: &Telemetry, turns: usize) -> f64 {
    let start = cpu_time::ThreadTime::now();
    for n in 0..turns {
        record_turn(telemetry, n);
        if (n + 1) % TURNS_PER_FLUSH == 0 {
            telemetry.flush();
        }
    }
    telemetry.flush();
    start.elapsed().as_nanos() as f64 / turns as f64
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let opts = Options::parse();
    let turns = opts.turns.max(1);
    let mut collector = Collector::start().await?;
    println!(
        "telemetry: {turns} turns of {SPANS_PER_TURN} spans each, recorded off and then on (OTLP/HTTP to {})",
        collector.url()
    );

    let off = Telemetry::off();
    let off_ns = tokio::task::spawn_blocking(move || recording_cost(&off, turns)).await?;

    let before = thread_cpu();
    let url = collector.url();
    let wall = Instant::now();
    // The collector reads while the turns are recorded, as a real one does.
    let expected = turns * SPANS_PER_TURN;
    let receiving = tokio::spawn(async move {
        collector
            .until(Duration::from_secs(120), "every span exported", |got| {
                got.len() >= expected
            })
            .await
            .map(|got| got.len())
    });
    let (on_ns, on) = tokio::task::spawn_blocking(move || -> anyhow::Result<(f64, Telemetry)> {
        let on = Telemetry::start("telemetry-bench", Some(("the bench", &url)))
            .context("starting telemetry")?;
        Ok((recording_cost(&on, turns), on))
    })
    .await??;
    let received = receiving.await??;
    // Read while the exporter's threads still run (they end with the last handle).
    let exporter_cpu = added_cpu(&before, &thread_cpu());
    drop(on);
    let wall_s = wall.elapsed().as_secs_f64();
    let exporter_ns = exporter_cpu as f64 / turns as f64;
    let on_total_us = (on_ns + exporter_ns) / 1000.0;
    println!("  off: {off_ns:.1} ns per turn on the recording thread");
    println!(
        "  on: {:.1} µs per turn recording + {:.1} µs exporting; {received} spans received in {wall_s:.1} s",
        on_ns / 1000.0,
        exporter_ns / 1000.0
    );
    println!(
        "SUMMARY telemetry_off_cost_per_turn: {off_ns:.1} ns CPU (the recording branch of one turn, {turns} turns)"
    );
    println!(
        "SUMMARY telemetry_on_cost_per_turn: {on_total_us:.1} µs CPU ({:.1} recording + {:.1} exporting {SPANS_PER_TURN} spans over OTLP/HTTP; {:.3}% of a {TURN_MS:.0} ms turn, every span received: {})",
        on_ns / 1000.0,
        exporter_ns / 1000.0,
        on_total_us / 10.0 / TURN_MS,
        received >= turns * SPANS_PER_TURN
    );
    Ok(())
}
