//! Printing: a table per configuration as it finishes, then the SUMMARY lines
//! with ratios against the baselines and the targets checked.

use crate::modes::{FixedRate, FlatOut, Latency};
use crate::payloads::Payload;
use crate::rig::System;

/// Everything measured for one system in one configuration.
#[derive(Debug, Clone)]
pub struct Measured {
    pub system: System,
    pub flat: FlatOut,
    pub open: FlatOut,
    pub rate: FixedRate,
    /// Peak RSS of the server process in bytes (none for raw TCP).
    pub peak_rss: Option<u64>,
}

/// One payload and subscriber count, all systems.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub payload: Payload,
    pub subs: usize,
    pub rows: Vec<Measured>,
}

impl Outcome {
    fn row(&self, system: System) -> Option<&Measured> {
        self.rows.iter().find(|m| m.system == system)
    }

    fn megabytes(&self, msgs_per_s: f64) -> f64 {
        msgs_per_s * self.payload.bytes.len() as f64 / 1e6
    }
}

/// Issue targets.
const MIN_RATIO_REDIS: f64 = 2.0;
const MIN_RATIO_RAW: f64 = 0.5;
const MAX_P99_MS: f64 = 0.5;
const MAX_RSS_MB: f64 = 50.0;

fn pct(ratio: f64) -> f64 {
    ratio * 100.0
}

fn us(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.2}"))
}

fn mb(bytes: Option<u64>) -> String {
    bytes.map_or("-".into(), |b| format!("{:.1}", b as f64 / 1e6))
}

pub fn print_table(o: &Outcome) {
    println!();
    println!(
        "== {} ({} B) x {} subscriber{} ==",
        o.payload.name,
        o.payload.bytes.len(),
        o.subs,
        if o.subs == 1 { "" } else { "s" }
    );
    println!(
        "{:<7} | {:<47} | {:<36} | {:<27} | server",
        "", "lossless flat out", "open loop", o.payload.rate_label
    );
    println!(
        "{:<7} | {:>8} {:>6} {:>7} {:>7} {:>6} {:>7} | {:>8} {:>8} {:>6} {:>6} {:>4} | {:>6} {:>6} {:>6} {:>6} | {:>8}",
        "system",
        "msg/s",
        "MB/s",
        "p50 ms",
        "p99 ms",
        "drop%",
        "srv us",
        "sent/s",
        "deliv/s",
        "drop%",
        "by srv",
        "disc",
        "p50 ms",
        "p99 ms",
        "max ms",
        "drop%",
        "peak RSS"
    );
    for m in &o.rows {
        println!(
            "{:<7} | {:>8.0} {:>6.1} {:>7.3} {:>7.3} {:>6.2} {:>7} | {:>8.0} {:>8.0} {:>6.2} {:>6} {:>4} | {:>6.3} {:>6.3} {:>6.3} {:>6.2} | {:>5} MB",
            m.system.label(),
            m.flat.delivered_per_s,
            o.megabytes(m.flat.delivered_per_s),
            m.flat.latency.p50_ms,
            m.flat.latency.p99_ms,
            pct(m.flat.drop_ratio),
            us(m.flat.server_cpu_us),
            m.open.sent_per_s,
            m.open.delivered_per_s,
            pct(m.open.drop_ratio),
            m.open
                .server_drop_ratio
                .map_or("-".into(), |r| format!("{:.2}", pct(r))),
            m.open.disconnected,
            m.rate.latency.p50_ms,
            m.rate.latency.p99_ms,
            m.rate.latency.max_ms,
            pct(m.rate.drop_ratio),
            mb(m.peak_rss),
        );
        let damaged = m.flat.damaged + m.open.damaged;
        if damaged > 0 {
            println!("        ! {damaged} deliveries reordered, duplicated or corrupted");
        }
    }
}

fn ratio(a: f64, b: f64) -> f64 {
    if b > 0.0 { a / b } else { f64::NAN }
}

fn pass(ok: bool) -> &'static str {
    if ok { "PASS" } else { "FAIL" }
}

fn lat(l: &Latency) -> String {
    format!(
        "p50 {:.3} ms p99 {:.3} ms over {} samples",
        l.p50_ms, l.p99_ms, l.samples
    )
}

pub fn print_summary(outcomes: &[Outcome]) {
    println!();
    for o in outcomes {
        let (Some(hub), Some(redis), Some(raw)) = (
            o.row(System::Hub),
            o.row(System::Redis),
            o.row(System::RawTcp),
        ) else {
            continue;
        };
        let name = format!("{} {} subs", o.payload.name, o.subs);
        println!(
            "SUMMARY hub {name}: {:.0} msg/s {:.1} MB/s (redis {:.0} msg/s, ratio {:.2}x; raw tcp {:.0} msg/s, ratio {:.2})",
            hub.flat.delivered_per_s,
            o.megabytes(hub.flat.delivered_per_s),
            redis.flat.delivered_per_s,
            ratio(hub.flat.delivered_per_s, redis.flat.delivered_per_s),
            raw.flat.delivered_per_s,
            ratio(hub.flat.delivered_per_s, raw.flat.delivered_per_s),
        );
        println!(
            "SUMMARY hub server cpu per delivery {name}: {} us (redis {} us, ratio {:.2})",
            us(hub.flat.server_cpu_us),
            us(redis.flat.server_cpu_us),
            ratio(
                hub.flat.server_cpu_us.unwrap_or(f64::NAN),
                redis.flat.server_cpu_us.unwrap_or(f64::NAN)
            ),
        );
        let total = |m: &Measured| {
            m.flat
                .client_cpu_us
                .map(|c| c + m.flat.server_cpu_us.unwrap_or(0.0))
        };
        println!(
            "SUMMARY hub client cpu per delivery {name}: {} us (redis {} us; raw tcp, writer included, {} us)",
            us(hub.flat.client_cpu_us),
            us(redis.flat.client_cpu_us),
            us(raw.flat.client_cpu_us),
        );
        println!(
            "SUMMARY hub clients + server cpu per delivery {name}: {} us (redis {} us, ratio {:.2}: the throughput ratio when the cores are saturated)",
            us(total(hub)),
            us(total(redis)),
            ratio(
                total(redis).unwrap_or(f64::NAN),
                total(hub).unwrap_or(f64::NAN)
            ),
        );
        println!(
            "SUMMARY hub open-loop {name}: {:.0} msg/s delivered, {:.1}% dropped (redis {:.0} msg/s, {:.1}% dropped, {} disconnected, ratio {:.2}x; raw tcp {:.0} msg/s, ratio {:.2})",
            hub.open.delivered_per_s,
            pct(hub.open.drop_ratio),
            redis.open.delivered_per_s,
            pct(redis.open.drop_ratio),
            redis.open.disconnected,
            ratio(hub.open.delivered_per_s, redis.open.delivered_per_s),
            raw.open.delivered_per_s,
            ratio(hub.open.delivered_per_s, raw.open.delivered_per_s),
        );
        println!(
            "SUMMARY hub latency {} {name}: {} (redis {}, p99 ratio {:.2}; raw tcp {})",
            o.payload.rate_label,
            lat(&hub.rate.latency),
            lat(&redis.rate.latency),
            ratio(hub.rate.latency.p99_ms, redis.rate.latency.p99_ms),
            lat(&raw.rate.latency),
        );
        println!(
            "SUMMARY hub latency flat out {name}: {} (redis {}; raw tcp {})",
            lat(&hub.flat.latency),
            lat(&redis.flat.latency),
            lat(&raw.flat.latency),
        );
        println!(
            "SUMMARY hub peak RSS {name}: {} MB (redis {} MB, ratio {:.2})",
            mb(hub.peak_rss),
            mb(redis.peak_rss),
            ratio(
                hub.peak_rss.unwrap_or(0) as f64,
                redis.peak_rss.unwrap_or(0) as f64
            ),
        );
    }
    print_targets(outcomes);
}

fn print_targets(outcomes: &[Outcome]) {
    println!();
    if let Some(o) = outcomes
        .iter()
        .find(|o| o.payload.name == "jpeg" && o.subs == 4)
        && let (Some(hub), Some(redis), Some(raw)) = (
            o.row(System::Hub),
            o.row(System::Redis),
            o.row(System::RawTcp),
        )
    {
        let vs_redis = ratio(hub.flat.delivered_per_s, redis.flat.delivered_per_s);
        let vs_raw = ratio(hub.flat.delivered_per_s, raw.flat.delivered_per_s);
        println!(
            "TARGET jpeg 4 subs throughput >= {MIN_RATIO_REDIS}x redis: {vs_redis:.2}x {}",
            pass(vs_redis >= MIN_RATIO_REDIS)
        );
        println!(
            "TARGET jpeg 4 subs throughput >= {MIN_RATIO_RAW} of raw tcp: {vs_raw:.2} {}",
            pass(vs_raw >= MIN_RATIO_RAW)
        );
    }
    let worst = outcomes
        .iter()
        .filter_map(|o| o.row(System::Hub).map(|m| (o, m.rate.latency.p99_ms)))
        .max_by(|a, b| a.1.total_cmp(&b.1));
    if let Some((o, p99)) = worst {
        println!(
            "TARGET hub p99 latency at fixed rates <= {MAX_P99_MS} ms: worst {p99:.3} ms ({} {} subs) {}",
            o.payload.name,
            o.subs,
            pass(p99 <= MAX_P99_MS)
        );
    }
    let rss = outcomes
        .iter()
        .filter(|o| o.subs == 16)
        .filter_map(|o| o.row(System::Hub).and_then(|m| m.peak_rss))
        .max();
    if let Some(rss) = rss {
        let mbytes = rss as f64 / 1e6;
        println!(
            "TARGET hub peak RSS at 16 subs <= {MAX_RSS_MB} MB: {mbytes:.1} MB {}",
            pass(mbytes <= MAX_RSS_MB)
        );
    }
}
