//! The fleet part of the ASR benchmark (`asr-bench`): 1, 2 and 3 satellite processes with default flags on one machine,
//! their throughput on one queue of utterances, and a short utterance decoded beside a long one.

use std::path::Path;
use std::time::Duration;

use crate::clips::ClipAudio;
use crate::fleet::{Done, Fleet};
use crate::jobs::write_jobs;

/// The figures of the three fleets.
pub struct FleetFigures {
    jobs: usize,
    /// Seconds for 1, 2 and 3 satellites to get through the queue.
    seconds: [f64; 3],
    /// Threads per decode the fleets ran with (the largest seen), 1, 2 and 3 satellites.
    threads: [usize; 3],
    /// The short utterance alone on one satellite, and alone with two on the machine (median round trips).
    short_alone_one: Duration,
    short_alone_two: Duration,
    /// The short one handed to the second satellite while the first decodes the long one.
    short_beside: Done,
    long_beside: Done,
    short_seconds: f64,
    long_seconds: f64,
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v.get(v.len() / 2).copied().unwrap_or_default()
}

/// Runs the fleets over `utterances` (four times over, `runs` passes of which the median counts: one pass lasts
/// only seconds, and a short pass is at the mercy of whatever else the machine does) and a long job made of the
/// longest clip whole.
pub fn fleets(
    model: &Path,
    clips: &[ClipAudio],
    utterances: &[Vec<f32>],
    runs: usize,
) -> anyhow::Result<FleetFigures> {
    let mut jobs: Vec<Vec<f32>> = (0..4).flat_map(|_| utterances.iter().cloned()).collect();
    let queue_len = jobs.len();
    let short = (0..utterances.len())
        .min_by_key(|&i| utterances[i].len())
        .ok_or_else(|| anyhow::anyhow!("no utterances to queue"))?;
    let longest = clips
        .iter()
        .max_by_key(|c| c.audio.len())
        .ok_or_else(|| anyhow::anyhow!("no clips"))?;
    let long = jobs.len();
    jobs.push(longest.audio.clone());

    let scratch = std::env::temp_dir().join(format!("whisper-sat-fleet-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let jobs_file = scratch.join("jobs.f32");
    write_jobs(&jobs_file, &jobs)?;
    let result = (|| -> anyhow::Result<FleetFigures> {
        let mut seconds = [0.0; 3];
        let mut threads = [0; 3];
        let mut short_alone_one = Duration::ZERO;
        let mut short_alone_two = Duration::ZERO;
        let mut beside = None;
        for n in 1..=3 {
            // Each fleet gets a core share of its own, so a fleet that is shutting down cannot count.
            let share = scratch.join(format!("cores-{n}"));
            let mut fleet = Fleet::start(n, model, &jobs_file, &share)?;
            let mut passes = (0..runs.max(1))
                .map(|_| fleet.throughput(queue_len))
                .collect::<anyhow::Result<Vec<f64>>>()?;
            passes.sort_by(f64::total_cmp);
            seconds[n - 1] = passes[passes.len() / 2];
            let alone: Vec<Done> = (0..runs.max(1))
                .map(|_| fleet.alone(short))
                .collect::<anyhow::Result<_>>()?;
            threads[n - 1] = alone.iter().map(|d| d.threads).max().unwrap_or(0);
            let alone = median(alone.iter().map(|d| d.round_trip).collect());
            match n {
                1 => short_alone_one = alone,
                2 => {
                    short_alone_two = alone;
                    // The long one gets a head start, so it holds its lease when the short one arrives; the
                    // pass whose short round trip is the median counts.
                    let mut pairs = (0..runs.max(1))
                        .map(|_| fleet.beside(long, short, Duration::from_millis(100)))
                        .collect::<anyhow::Result<Vec<(Done, Done)>>>()?;
                    pairs.sort_by_key(|(_, s)| s.round_trip);
                    beside = Some(pairs[pairs.len() / 2]);
                }
                _ => {}
            }
        }
        let (long_beside, short_beside) =
            beside.ok_or_else(|| anyhow::anyhow!("the two-satellite fleet did not run"))?;
        Ok(FleetFigures {
            jobs: queue_len,
            seconds,
            threads,
            short_alone_one,
            short_alone_two,
            short_beside,
            long_beside,
            short_seconds: utterances[short].len() as f64 / 16_000.0,
            long_seconds: longest.seconds(),
        })
    })();
    let _ = std::fs::remove_dir_all(&scratch);
    result
}

impl FleetFigures {
    /// The SUMMARY lines.
    pub fn summary(&self) -> Vec<String> {
        let rate = |i: usize| self.jobs as f64 / self.seconds[i];
        let ms = |d: Duration| d.as_secs_f64() * 1000.0;
        let mut lines = Vec::new();
        for n in [2, 3] {
            lines.push(format!(
                "SUMMARY asr throughput {n} satellites (default flags): {:.2} utterances/s (baseline 1 satellite {:.2}/s, ratio {:.2}; {} utterances, {} thread(s) per decode against {})",
                rate(n - 1),
                rate(0),
                rate(n - 1) / rate(0),
                self.jobs,
                self.threads[n - 1],
                self.threads[0],
            ));
        }
        lines.push(format!(
            "SUMMARY asr short utterance ({:.1} s) beside a long one ({:.1} s) on another satellite: {:.0} ms, of which waiting for a core {:.0} ms (baseline alone, 2 satellites on the machine: {:.0} ms, ratio {:.2}; the long one took {:.0} ms)",
            self.short_seconds,
            self.long_seconds,
            ms(self.short_beside.round_trip),
            ms(self.short_beside.core_wait),
            ms(self.short_alone_two),
            ms(self.short_beside.round_trip) / ms(self.short_alone_two),
            ms(self.long_beside.round_trip),
        ));
        lines.push(format!(
            "SUMMARY asr short utterance alone with 2 satellites on the machine: {:.0} ms on {} thread(s) (baseline 1 satellite: {:.0} ms on {}, ratio {:.2})",
            ms(self.short_alone_two),
            self.threads[1],
            ms(self.short_alone_one),
            self.threads[0],
            ms(self.short_alone_two) / ms(self.short_alone_one),
        ));
        lines
    }
}
