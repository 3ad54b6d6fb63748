//! The soak (`make soak`, not part of `make test`): the whole agent for a long while, as a person uses it. A real
//! release `robot-agent` with every module and the recorder on, two `whisper-sat` satellites, and headless Chromium
//! holding the page with a fake microphone and camera that loop fixture media: a portrait then a QR code, and two
//! spoken questions in each 20 s loop. Every minute it samples each of our processes' RSS, open descriptors and
//! threads, and the hub's drops; every turn's transcript, the rule that answered and its voice-to-voice time (the
//! observer's `Agent.latency`, end of speech to the first reply PCM).
//!
//! It prints a table and SUMMARY lines, writes the samples as CSV beside the Markdown report (`--write`), and the
//! targets: RSS growth after the first five minutes <= 5 MB per process, no descriptor growth, every question
//! answered, p95 in the last five minutes within 10% of the first five.
//!
//! Each process's RSS is also fitted from minute 5 on (MiB per hour): over a long run (`make soak HOURS=N`) a leak
//! keeps its slope and a high-water mark reached once does not.
//!
//! Options: `--minutes N` (default 30), `--write PATH` (Markdown report; the CSV goes to PATH with `.csv`).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use agent_bench::percentile;
use agent_contract::channels as ch;
use agent_contract::latency::TurnLatency;
use agent_contract::rules::RuleChange;
use agent_contract::transcript::TranscriptMessage;
use agent_tests::browser_chromium::{Chromium, Devices};
use agent_tests::browser_media::prepare_pipeline;
use agent_tests::{Agent, AgentOptions, DataDir, Satellite};
use anyhow::{Context, bail};
use clap::Parser;

/// How often the processes are sampled.
const SAMPLE_EVERY: Duration = Duration::from_secs(60);
/// The early and late windows compared.
const WINDOW: Duration = Duration::from_secs(300);

/// One process's figures at one moment.
#[derive(Debug, Clone, Copy, Default)]
struct Proc {
    rss_kib: u64,
    fds: usize,
    threads: u64,
}

impl Proc {
    fn rss_mib(&self) -> f64 {
        self.rss_kib as f64 / 1024.0
    }
}

fn sample(pid: u32) -> anyhow::Result<Proc> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let field = |name: &str| -> u64 {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    Ok(Proc {
        rss_kib: field("VmRSS:"),
        threads: field("Threads:"),
        fds: std::fs::read_dir(format!("/proc/{pid}/fd"))?.count(),
    })
}

/// One row of the table.
#[derive(Debug, Clone)]
struct Row {
    minute: u64,
    procs: Vec<Proc>,
    dropped: u64,
    turns: usize,
}

/// A turn as the watcher saw it.
#[derive(Debug, Clone)]
struct Turn {
    at: Duration,
    heard: String,
    answer: String,
    total_ms: f64,
}

#[derive(Default)]
struct Seen {
    /// The last final transcript and the last rule change, waiting for their turn's latency.
    heard: String,
    answer: String,
    /// When each final transcript and each spoken answer (a rule's `say`) came.
    finals: Vec<Duration>,
    says: Vec<Duration>,
    turns: Vec<Turn>,
}

/// How long after a question its answer may start and still count as its answer.
const ANSWER_WITHIN: Duration = Duration::from_secs(15);

/// Questions (final transcripts) followed by a spoken answer within [`ANSWER_WITHIN`].
fn answered(finals: &[Duration], says: &[Duration]) -> usize {
    finals
        .iter()
        .filter(|q| says.iter().any(|a| *a >= **q && *a <= **q + ANSWER_WITHIN))
        .count()
}

/// The least-squares slope of `points` (x, y); 0 for fewer than two distinct x.
fn least_squares_slope(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    if points.len() < 2 {
        return 0.0;
    }
    let mean_x = points.iter().map(|p| p.0).sum::<f64>() / n;
    let mean_y = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = points.iter().map(|p| (p.0 - mean_x).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mean_x) * (p.1 - mean_y)).sum();
    if sxx > 0.0 { sxy / sxx } else { 0.0 }
}

fn lock(seen: &Mutex<Seen>) -> std::sync::MutexGuard<'_, Seen> {
    seen.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The soak: the whole agent with a browser, two satellites and the recorder for a long while, sampled every
/// minute (`make soak`).
#[derive(Debug, clap::Parser)]
struct Args {
    /// How long (at least 11: the first and last five minutes are compared).
    #[arg(long, default_value_t = 30)]
    minutes: u64,
    /// Write the Markdown report here (the samples' CSV beside it, with `.csv`).
    #[arg(long, value_name = "PATH")]
    write: Option<PathBuf>,
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let Args { minutes, write } = Args::parse();
    if minutes < 11 {
        bail!("--minutes must be at least 11: the first and last five minutes are compared");
    }
    let scratch = tempfile::Builder::new().prefix("soak-").tempdir()?;
    let media = prepare_pipeline(scratch.path()).context("converting the fixture media")?;
    let data = DataDir::new()?;
    let recording = data.path().join("soak.mcap");
    let agent = Agent::start_with(
        &data,
        AgentOptions {
            args: vec!["--record".into(), recording.display().to_string()],
            log: Some("warn".into()),
            ..Default::default()
        },
    )
    .await?;
    let sats = [
        Satellite::start(&agent, "soak-asr-1").await?,
        Satellite::start(&agent, "soak-asr-2").await?,
    ];
    let mut pids = vec![("robot-agent".to_string(), agent.pid().context("agent pid")?)];
    for s in &sats {
        pids.push((s.name.clone(), s.child.id().context("satellite pid")?));
    }
    let watcher = agent.client("soak-watch").await?;
    let seen = Arc::new(Mutex::new(Seen::default()));
    let started = Instant::now();
    spawn_watchers(&watcher, seen.clone(), started).await?;

    let browser = Chromium::launch_with(&Devices::Granted(media)).await?;
    let tab = browser.open(&agent.page_url("autostart=1&aec=0")).await?;
    browser
        .wait_for(
            &tab,
            "window.agentDebug && agentDebug.role === 'holder' && agentDebug.sent.audio > 0",
            Duration::from_secs(60),
        )
        .await
        .context("the page did not start streaming")?;
    println!(
        "soak: {minutes} min, robot-agent (every module, recording), 2 whisper-sat, headless Chromium looping \
         fixture media with two questions every 20 s"
    );
    println!("{}", header(&pids));

    let mut rows = Vec::new();
    let end = started + Duration::from_secs(minutes * 60);
    let mut next = started;
    while next <= end {
        tokio::time::sleep_until(next.into()).await;
        let mut procs = Vec::new();
        for (name, pid) in &pids {
            procs.push(sample(*pid).with_context(|| format!("{name} ({pid}) is gone"))?);
        }
        let dropped = watcher
            .channels()
            .await?
            .iter()
            .map(|c| c.stats.dropped)
            .sum();
        let row = Row {
            minute: started.elapsed().as_secs() / 60,
            procs,
            dropped,
            turns: lock(&seen).turns.len(),
        };
        println!("{}", line(&row));
        rows.push(row);
        next += SAMPLE_EVERY;
    }
    browser.quit().await;
    let seen = lock(&seen);
    let report = Report::new(
        &pids,
        &rows,
        &seen.turns,
        seen.finals.len(),
        answered(&seen.finals, &seen.says),
    );
    for l in report.summary() {
        println!("{l}");
    }
    if let Some(path) = write {
        std::fs::write(&path, report.markdown(minutes))
            .with_context(|| format!("writing {}", path.display()))?;
        let csv = path.with_extension("csv");
        std::fs::write(&csv, report.csv())?;
        println!("wrote {} and {}", path.display(), csv.display());
    }
    drop(sats);
    Ok(())
}

/// Follows the transcripts, the rules and the turn latencies.
async fn spawn_watchers(
    client: &flow::Client,
    seen: Arc<Mutex<Seen>>,
    started: Instant,
) -> anyhow::Result<()> {
    let transcripts = client.subscribe(ch::TRANSCRIPT.name).await?;
    let rules = client.subscribe(ch::RULES.name).await?;
    let latency = client.subscribe(ch::LATENCY.name).await?;
    let s = seen.clone();
    tokio::spawn(async move {
        while let Some(d) = transcripts.recv().await {
            if let Ok(t) = serde_json::from_slice::<TranscriptMessage>(&d.payload)
                && t.is_final
                && !t.text.trim().is_empty()
            {
                let mut seen = lock(&s);
                seen.heard = t.text.trim().to_string();
                seen.finals.push(started.elapsed());
            }
        }
    });
    let s = seen.clone();
    tokio::spawn(async move {
        while let Some(d) = rules.recv().await {
            if let Ok(r) = serde_json::from_slice::<RuleChange>(&d.payload)
                && r.action.contains("say")
            {
                let mut seen = lock(&s);
                seen.answer = format!("{} ({})", r.action, r.rule);
                seen.says.push(started.elapsed());
            }
        }
    });
    tokio::spawn(async move {
        while let Some(d) = latency.recv().await {
            if let Ok(l) = serde_json::from_slice::<TurnLatency>(&d.payload) {
                let mut seen = lock(&seen);
                let turn = Turn {
                    at: started.elapsed(),
                    heard: std::mem::take(&mut seen.heard),
                    answer: std::mem::take(&mut seen.answer),
                    total_ms: l.total_ms,
                };
                seen.turns.push(turn);
            }
        }
    });
    Ok(())
}

/// Today's date, `YYYY-MM-DD` (UTC).
fn taken_on() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    agent_bench::summary::utc_date(secs)
}

fn header(pids: &[(String, u32)]) -> String {
    let mut h = String::from("min");
    for (name, _) in pids {
        let _ = write!(h, " | {name} rss MiB fds thr");
    }
    h + " | drops | turns"
}

fn line(r: &Row) -> String {
    let mut l = format!("{:>3}", r.minute);
    for p in &r.procs {
        let _ = write!(l, " | {:>7.1} {:>4} {:>3}", p.rss_mib(), p.fds, p.threads);
    }
    l + &format!(" | {:>5} | {:>5}", r.dropped, r.turns)
}

/// What the run shows against its targets.
struct Report<'a> {
    pids: &'a [(String, u32)],
    rows: &'a [Row],
    turns: &'a [Turn],
    finals: usize,
    answered: usize,
}

impl<'a> Report<'a> {
    fn new(
        pids: &'a [(String, u32)],
        rows: &'a [Row],
        turns: &'a [Turn],
        finals: usize,
        answered: usize,
    ) -> Self {
        Report {
            pids,
            rows,
            turns,
            finals,
            answered,
        }
    }

    /// Each process's RSS trend from minute 5 on, in MiB per hour: the least-squares slope over every minute's
    /// sample, so that a long run tells a steady leak (a slope that holds) from a high-water mark reached once (a
    /// step, then flat: the slope falls as the run goes on), which the end-to-end difference cannot.
    fn slopes(&self) -> Vec<f64> {
        let settled: Vec<&Row> = self.rows.iter().filter(|r| r.minute >= 5).collect();
        (0..self.pids.len())
            .map(|i| {
                let points: Vec<(f64, f64)> = settled
                    .iter()
                    .map(|r| (r.minute as f64 / 60.0, r.procs[i].rss_mib()))
                    .collect();
                least_squares_slope(&points)
            })
            .collect()
    }

    /// RSS growth (MiB) and descriptor growth per process from minute 5 to the end.
    fn growth(&self) -> Vec<(String, f64, i64, i64)> {
        let settled = self.rows.iter().find(|r| r.minute >= 5);
        let (Some(a), Some(b)) = (settled, self.rows.last()) else {
            return Vec::new();
        };
        self.pids
            .iter()
            .enumerate()
            .map(|(i, (name, _))| {
                let (pa, pb) = (a.procs[i], b.procs[i]);
                (
                    name.clone(),
                    (pb.rss_kib as f64 - pa.rss_kib as f64) / 1024.0,
                    pb.fds as i64 - pa.fds as i64,
                    pb.threads as i64 - pa.threads as i64,
                )
            })
            .collect()
    }

    /// Voice-to-voice p50 and p95 of the turns in the first and last five minutes.
    fn windows(&self) -> ((f64, f64, usize), (f64, f64, usize)) {
        let total = self.turns.last().map_or(Duration::ZERO, |t| t.at);
        let pick = |f: &dyn Fn(&Turn) -> bool| {
            let v: Vec<f64> = self
                .turns
                .iter()
                .filter(|t| f(t))
                .map(|t| t.total_ms)
                .collect();
            (percentile(&v, 0.5), percentile(&v, 0.95), v.len())
        };
        let first = pick(&|t| t.at <= WINDOW);
        let last = pick(&|t| t.at + WINDOW >= total);
        (first, last)
    }

    fn summary(&self) -> Vec<String> {
        let mut out = Vec::new();
        let slopes = self.slopes();
        for ((name, rss, fds, threads), slope) in self.growth().into_iter().zip(slopes) {
            out.push(format!(
                "SUMMARY soak {name}: RSS growth after minute 5 {rss:+.1} MiB (target <= 5), trend {slope:+.2} MiB/h, descriptors {fds:+}, threads {threads:+}"
            ));
        }
        let ((p50a, p95a, na), (p50b, p95b, nb)) = self.windows();
        out.push(format!(
            "SUMMARY soak voice-to-voice: first 5 min p50 {p50a:.0} ms p95 {p95a:.0} ms ({na} turns); last 5 min p50 {p50b:.0} ms p95 {p95b:.0} ms ({nb} turns); p95 ratio {:.2} (target <= 1.10)",
            p95b / p95a
        ));
        let unanswered = self.turns.iter().filter(|t| t.answer.is_empty()).count();
        let dropped = self.rows.last().map_or(0, |r| r.dropped);
        out.push(format!(
            "SUMMARY soak turns: {} questions heard (final transcripts), {} answered aloud within {} s (target: all), {} with a voice-to-voice figure, {unanswered} of those without a rule's say seen, hub drops {dropped}",
            self.finals,
            self.answered,
            ANSWER_WITHIN.as_secs(),
            self.turns.len()
        ));
        out
    }

    fn csv(&self) -> String {
        let mut s = String::from("minute");
        for (name, _) in self.pids {
            let _ = write!(s, ",{name}_rss_mib,{name}_fds,{name}_threads");
        }
        s.push_str(",drops,turns\n");
        for r in self.rows {
            let _ = write!(s, "{}", r.minute);
            for p in &r.procs {
                let _ = write!(s, ",{:.1},{},{}", p.rss_mib(), p.fds, p.threads);
            }
            let _ = writeln!(s, ",{},{}", r.dropped, r.turns);
        }
        s.push_str("\nturn_s,voice_to_voice_ms,heard,answer\n");
        for t in self.turns {
            let _ = writeln!(
                s,
                "{},{:.0},{:?},{:?}",
                t.at.as_secs(),
                t.total_ms,
                t.heard,
                t.answer
            );
        }
        s
    }

    fn markdown(&self, minutes: u64) -> String {
        let mut m = format!(
            "# Soak\n\n`make soak MINUTES={minutes}` (or `HOURS=N`): see `bench/soak/main.rs` for what runs. Taken on {} at commit \
             {}.\n\n",
            taken_on(),
            agent_bench::summary::current_commit()
        );
        m.push_str("```text\n");
        for l in self.summary() {
            m.push_str(&l);
            m.push('\n');
        }
        m.push_str("```\n\n![RSS, descriptors and voice-to-voice over the soak](soak.png)\n\n");
        m.push_str("| ");
        m.push_str(&header(self.pids));
        m.push_str(" |\n|");
        m.push_str(&"---|".repeat(2 + self.pids.len() + 1));
        m.push('\n');
        for r in self.rows {
            m.push_str("| ");
            m.push_str(&line(r));
            m.push_str(" |\n");
        }
        m.push_str(
            "\n## Turns\n\n| at (s) | voice to voice (ms) | heard | answer |\n|---|---|---|---|\n",
        );
        let mut by_text: BTreeMap<&str, usize> = BTreeMap::new();
        for t in self.turns {
            *by_text.entry(t.heard.as_str()).or_default() += 1;
            let _ = writeln!(
                m,
                "| {} | {:.0} | {} | {} |",
                t.at.as_secs(),
                t.total_ms,
                t.heard.replace('|', "/"),
                t.answer.replace('|', "/")
            );
        }
        m.push_str("\n## What it heard, by count\n\n");
        for (text, n) in by_text {
            let _ = writeln!(m, "- {n} x {text:?}");
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::least_squares_slope;

    #[test]
    fn a_steady_leak_shows_its_rate_and_a_step_then_flat_shows_a_falling_one() {
        // 3 MiB per hour, sampled every minute for two hours.
        let steady: Vec<(f64, f64)> = (0..120)
            .map(|m| (m as f64 / 60.0, 100.0 + 3.0 * m as f64 / 60.0))
            .collect();
        assert!((least_squares_slope(&steady) - 3.0).abs() < 1e-9);
        // A step of 8 MiB at minute 10, flat after: over 30 minutes it looks like growth, over two hours much less.
        let step = |minutes: u32| -> Vec<(f64, f64)> {
            (5..minutes)
                .map(|m| (f64::from(m) / 60.0, if m < 10 { 100.0 } else { 108.0 }))
                .collect()
        };
        let short = least_squares_slope(&step(30));
        let long = least_squares_slope(&step(120));
        assert!(short > 2.0 * long && long > 0.0, "{short} {long}");
        assert_eq!(least_squares_slope(&[(1.0, 5.0)]), 0.0);
    }
}
