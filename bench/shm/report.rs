//! Printing: a table per payload (deliveries/s and CPU per delivery for every mode and subscriber count), the
//! latency table, then the SUMMARY lines with the targets as ratios, and TARGET verdicts.

use crate::drive::{Flat, Latency};
use crate::payloads::Payload;
use crate::rig::Mode;

/// One measured cell: a payload, a subscriber count, a mode.
#[derive(Debug, Clone)]
pub struct Cell {
    pub payload: &'static str,
    pub subs: usize,
    pub mode: Mode,
    pub flat: Flat,
}

/// Everything one run measured.
#[derive(Debug, Default)]
pub struct Results {
    pub payloads: Vec<Payload>,
    pub subs: Vec<usize>,
    pub modes: Vec<Mode>,
    pub cells: Vec<Cell>,
    /// The fixed-rate runs, per mode.
    pub latency: Vec<(Mode, Latency)>,
    /// What the fixed-rate runs were: e.g. `30 Hz, 1 MB, 4 subs`.
    pub latency_label: String,
    /// The most shared-memory file mappings the bench process held during an `shm` cell, over those it held before.
    pub memfd_mappings: usize,
}

/// Issue 39's targets.
const MIN_RATIO_RAW: f64 = 3.0;
const MAX_CPU_RATIO_TCP: f64 = 0.2;
const MAX_P99_MS: f64 = 0.2;
/// The subscriber count the targets are read at.
const TARGET_SUBS: usize = 4;

impl Results {
    fn cell(&self, payload: &str, subs: usize, mode: Mode) -> Option<&Flat> {
        self.cells
            .iter()
            .find(|c| c.payload == payload && c.subs == subs && c.mode == mode)
            .map(|c| &c.flat)
    }

    fn latency(&self, mode: Mode) -> Option<&Latency> {
        self.latency
            .iter()
            .find(|(m, _)| *m == mode)
            .map(|(_, l)| l)
    }

    /// `f(shm) / f(other)` for a payload at the target subscriber count.
    fn ratio(&self, payload: &str, other: Mode, f: impl Fn(&Flat) -> f64) -> f64 {
        match (
            self.cell(payload, TARGET_SUBS, Mode::Shm),
            self.cell(payload, TARGET_SUBS, other),
        ) {
            (Some(a), Some(b)) => ratio(f(a), f(b)),
            _ => f64::NAN,
        }
    }
}

fn ratio(a: f64, b: f64) -> f64 {
    if b > 0.0 { a / b } else { f64::NAN }
}

fn pass(ok: bool) -> &'static str {
    if ok { "PASS" } else { "FAIL" }
}

/// The table of one payload, printed once its cells are measured.
pub fn print_table(r: &Results, payload: &Payload) {
    println!();
    println!("== {} ==", payload.label());
    let mut head = format!("{:<9}", "mode");
    for &n in &r.subs {
        let title = format!("{n} sub{}", if n == 1 { "" } else { "s" });
        head.push_str(&format!(
            "| {title:>8}: {:>9} {:>7} {:>8} ",
            "deliv/s", "GB/s", "cpu us"
        ));
    }
    println!("{head}");
    for &mode in &r.modes {
        let mut line = format!("{:<9}", mode.label());
        for &n in &r.subs {
            match r.cell(payload.name, n, mode) {
                Some(f) => line.push_str(&format!(
                    "| {:>8}  {:>9.0} {:>7.2} {:>8.2} ",
                    "",
                    f.deliveries_per_s,
                    f.deliveries_per_s * payload.bytes.len() as f64 / 1e9,
                    f.cpu_us
                )),
                None => line.push_str(&format!("| {:>8}  {:>9} {:>7} {:>8} ", "", "-", "-", "-")),
            }
        }
        println!("{line}");
        for &n in &r.subs {
            if let Some(f) = r.cell(payload.name, n, mode)
                && (f.missing > 0 || f.damaged > 0)
            {
                println!(
                    "          ! {} x {n}: {} deliveries missing, {} damaged or out of order",
                    mode.label(),
                    f.missing,
                    f.damaged
                );
            }
        }
    }
    println!(
        "(cpu us: CPU time per delivery of the bench process, publisher and subscribers, plus the hub's)"
    );
}

fn lat(l: Option<&Latency>) -> String {
    l.map_or("-".into(), |l| {
        format!(
            "p50 {:.3} ms p99 {:.3} ms max {:.3} ms over {} samples",
            l.p50_ms, l.p99_ms, l.max_ms, l.samples
        )
    })
}

pub fn print_latency(r: &Results) {
    println!();
    println!("== latency at {} ==", r.latency_label);
    for (mode, l) in &r.latency {
        println!("{:<9}| {}", mode.label(), lat(Some(l)));
    }
}

/// A cell's rate and CPU per delivery, with the hub's part of the CPU where there is a hub.
fn flat(f: Option<&Flat>) -> String {
    f.map_or("-".into(), |f| {
        if f.hub_cpu_us > 0.0 {
            format!(
                "{:.0} deliveries/s, {:.2} us cpu/delivery of which {:.2} in the hub",
                f.deliveries_per_s, f.cpu_us, f.hub_cpu_us
            )
        } else {
            format!(
                "{:.0} deliveries/s, {:.2} us cpu/delivery",
                f.deliveries_per_s, f.cpu_us
            )
        }
    })
}

pub fn print_summary(r: &Results) {
    println!();
    for p in &r.payloads {
        for &n in &r.subs {
            let Some(shm) = r.cell(p.name, n, Mode::Shm) else {
                continue;
            };
            let others: Vec<String> = [Mode::ShmFrames, Mode::HubTcp, Mode::RawTcp, Mode::Iceoryx2]
                .into_iter()
                .map(|m| format!("{} {}", m.label(), flat(r.cell(p.name, n, m))))
                .collect();
            println!(
                "SUMMARY shm {} {n} subs: {} ({})",
                p.human(),
                flat(Some(shm)),
                others.join("; ")
            );
        }
    }
    let per_payload = |f: &dyn Fn(&str) -> f64| -> String {
        r.payloads
            .iter()
            .map(|p| format!("{} {:.2}", p.human(), f(p.name)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let rate = |f: &Flat| f.deliveries_per_s;
    let cpu = |f: &Flat| f.cpu_us;
    println!(
        "SUMMARY shm deliveries/s over raw-tcp, {TARGET_SUBS} subs: {}",
        per_payload(&|p| r.ratio(p, Mode::RawTcp, rate))
    );
    println!(
        "SUMMARY shm cpu per delivery over hub-tcp, {TARGET_SUBS} subs: {}",
        per_payload(&|p| r.ratio(p, Mode::HubTcp, cpu))
    );
    if r.modes.contains(&Mode::ShmFrames) {
        println!(
            "SUMMARY shm release ring over Release frames (shm-frames), {TARGET_SUBS} subs: deliveries/s {}; cpu per \
             delivery {}",
            per_payload(&|p| r.ratio(p, Mode::ShmFrames, rate)),
            per_payload(&|p| r.ratio(p, Mode::ShmFrames, cpu))
        );
    }
    println!(
        "SUMMARY shm against the iceoryx2 floor, {TARGET_SUBS} subs: deliveries/s {}; cpu per delivery {}",
        per_payload(&|p| r.ratio(p, Mode::Iceoryx2, rate)),
        per_payload(&|p| r.ratio(p, Mode::Iceoryx2, cpu))
    );
    println!(
        "SUMMARY shm latency {}: {} (shm-frames {}; hub-tcp {}; raw-tcp {}; iceoryx2 {})",
        r.latency_label,
        lat(r.latency(Mode::Shm)),
        lat(r.latency(Mode::ShmFrames)),
        lat(r.latency(Mode::HubTcp)),
        lat(r.latency(Mode::RawTcp)),
        lat(r.latency(Mode::Iceoryx2)),
    );
    if r.modes.contains(&Mode::Shm) {
        if r.memfd_mappings > 0 {
            println!(
                "SUMMARY shm data path: shared memory ({} memfd mappings in the subscribers' process)",
                r.memfd_mappings
            );
        } else {
            println!(
                "SUMMARY shm data path: bytes over the Unix socket (no memfd mapping in the subscribers' process)"
            );
        }
    }
    print_targets(r);
}

fn print_targets(r: &Results) {
    println!();
    let large: Vec<&Payload> = r
        .payloads
        .iter()
        .filter(|p| p.bytes.len() >= 64 * 1024)
        .collect();
    let verdict = |f: &dyn Fn(&str) -> f64, ok: &dyn Fn(f64) -> bool| -> (String, bool) {
        let figures: Vec<(String, f64)> = large
            .iter()
            .map(|p| (p.human().to_owned(), f(p.name)))
            .collect();
        let all_ok = !figures.is_empty() && figures.iter().all(|(_, v)| ok(*v));
        let text = figures
            .iter()
            .map(|(name, v)| format!("{name} {v:.2}"))
            .collect::<Vec<_>>()
            .join(", ");
        (text, all_ok)
    };
    if r.modes.contains(&Mode::Shm) && r.modes.contains(&Mode::RawTcp) {
        let (text, ok) = verdict(
            &|p| r.ratio(p, Mode::RawTcp, |f| f.deliveries_per_s),
            &|v| v >= MIN_RATIO_RAW,
        );
        println!(
            "TARGET shm deliveries/s >= {MIN_RATIO_RAW}x raw-tcp at >= 64 KB, {TARGET_SUBS} subs: {text} {}",
            pass(ok)
        );
    }
    if r.modes.contains(&Mode::Shm) && r.modes.contains(&Mode::HubTcp) {
        let (text, ok) = verdict(&|p| r.ratio(p, Mode::HubTcp, |f| f.cpu_us), &|v| {
            v <= MAX_CPU_RATIO_TCP
        });
        println!(
            "TARGET shm cpu per delivery <= {MAX_CPU_RATIO_TCP}x hub-tcp at >= 64 KB, {TARGET_SUBS} subs: {text} {}",
            pass(ok)
        );
    }
    if let Some(l) = r.latency(Mode::Shm) {
        println!(
            "TARGET shm p99 latency at {} <= {MAX_P99_MS} ms: {:.3} ms {}",
            r.latency_label,
            l.p99_ms,
            pass(l.p99_ms <= MAX_P99_MS)
        );
    }
}
