//! Shared benchmark plumbing: a process's CPU time from /proc, percentiles of samples, the raw-TCP baseline's
//! sockets ([`raw_tcp`]), the knowledge folder's questions ([`knowledge_set`]), and the [`summary`] blocks of
//! docs/benchmarks.md that `bench-summary` rewrites from the benches' output.

pub mod knowledge_set;
pub mod raw_tcp;
pub mod summary;

use anyhow::Context;

/// utime + stime of `pid`, in clock ticks (USER_HZ, 100 on every architecture Debian ships).
pub fn cpu_ticks(pid: u32) -> anyhow::Result<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    // The command name (field 2) may contain spaces; fields after the closing parenthesis are plain.
    let rest = stat
        .rsplit_once(')')
        .map(|(_, r)| r)
        .context("malformed /proc stat")?;
    let f: Vec<&str> = rest.split_whitespace().collect();
    // After ')': state is field 3, so utime (14) and stime (15) are at indices 11 and 12.
    Ok(f.get(11).context("utime")?.parse::<u64>()? + f.get(12).context("stime")?.parse::<u64>()?)
}

/// CPU nanoseconds used by the living threads of `pid` (`/proc/PID/task/*/schedstat`, finer than [`cpu_ticks`]):
/// threads that ended meanwhile drop out, which a server's threads never do.
pub fn cpu_ns(pid: u32) -> Option<u64> {
    let mut total = 0;
    for task in std::fs::read_dir(format!("/proc/{pid}/task")).ok()? {
        let path = task.ok()?.path().join("schedstat");
        let text = std::fs::read_to_string(path).unwrap_or_default();
        total += text
            .split_whitespace()
            .next()
            .and_then(|ns| ns.parse::<u64>().ok())
            .unwrap_or(0);
    }
    Some(total)
}

/// Seconds per clock tick of [`cpu_ticks`].
pub const SECONDS_PER_TICK: f64 = 0.01;

/// The `q` quantile (0..=1) of `v`, by the nearest index; NaN for no samples.
pub fn percentile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}
