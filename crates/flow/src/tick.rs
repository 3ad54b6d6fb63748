//! Pulses: FastTick, SlowTick and OneSecTick on timers, with jitter statistics.
//!
//! The paper's event loop emits three ticks; here each is a tokio interval, so
//! waiting costs nothing (no spinning) and a late tick is skipped rather than
//! fired in a burst. Each tick's lateness against its schedule is recorded so
//! that a busy or starved process shows up as jitter.

use std::time::Duration;

use tokio::time::{Instant, Interval, MissedTickBehavior};

/// Which pulse fired.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Tick {
    Fast,
    Slow,
    OneSec,
}

/// Periods of the pulses; `None` turns a pulse off.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TickConfig {
    pub fast: Option<Duration>,
    pub slow: Option<Duration>,
    pub one_sec: bool,
}

impl Default for TickConfig {
    /// The paper's defaults: FastTick 10 ms, SlowTick 100 ms, OneSecTick 1 s.
    fn default() -> Self {
        TickConfig {
            fast: Some(Duration::from_millis(10)),
            slow: Some(Duration::from_millis(100)),
            one_sec: true,
        }
    }
}

/// Lateness statistics of one pulse, in microseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct JitterStats {
    pub ticks: u64,
    pub mean_us: f64,
    pub p50_us: u64,
    pub p99_us: u64,
    pub max_us: u64,
}

/// Log2-bucketed histogram of lateness: constant memory, cheap to update.
#[derive(Debug, Clone, Default)]
pub struct JitterMeter {
    buckets: [u64; 32],
    count: u64,
    sum_us: u64,
    max_us: u64,
}

impl JitterMeter {
    pub fn record(&mut self, late: Duration) {
        let us = u64::try_from(late.as_micros()).unwrap_or(u64::MAX);
        let bucket = (64 - us.leading_zeros()).min(31) as usize;
        self.buckets[bucket] += 1;
        self.count += 1;
        self.sum_us = self.sum_us.saturating_add(us);
        self.max_us = self.max_us.max(us);
    }

    /// Percentiles are bucket upper bounds (a power of two), capped by the maximum seen.
    pub fn stats(&self) -> JitterStats {
        let quantile = |q: f64| -> u64 {
            let target = (self.count as f64 * q).ceil() as u64;
            let mut seen = 0;
            for (i, n) in self.buckets.iter().enumerate() {
                seen += n;
                if seen >= target && *n > 0 {
                    let upper = if i == 0 { 0 } else { (1u64 << i) - 1 };
                    return upper.min(self.max_us);
                }
            }
            self.max_us
        };
        if self.count == 0 {
            return JitterStats::default();
        }
        JitterStats {
            ticks: self.count,
            mean_us: self.sum_us as f64 / self.count as f64,
            p50_us: quantile(0.5),
            p99_us: quantile(0.99),
            max_us: self.max_us,
        }
    }
}

/// The three pulses of one task, merged into one stream of ticks.
#[derive(Debug)]
pub struct Pulses {
    fast: Option<Interval>,
    slow: Option<Interval>,
    one_sec: Option<Interval>,
    pub fast_jitter: JitterMeter,
    pub slow_jitter: JitterMeter,
    pub one_sec_jitter: JitterMeter,
    /// How late the tick that [`Pulses::next`] returned last fired, for callers that keep their own histogram.
    pub last_late: Duration,
}

fn interval(period: Duration) -> Interval {
    let mut i = tokio::time::interval_at(Instant::now() + period, period);
    i.set_missed_tick_behavior(MissedTickBehavior::Skip);
    i
}

impl Pulses {
    pub fn new(config: TickConfig) -> Self {
        Pulses {
            fast: config.fast.map(interval),
            slow: config.slow.map(interval),
            one_sec: config.one_sec.then(|| interval(Duration::from_secs(1))),
            fast_jitter: JitterMeter::default(),
            slow_jitter: JitterMeter::default(),
            one_sec_jitter: JitterMeter::default(),
            last_late: Duration::ZERO,
        }
    }

    /// Waits for the next tick of any enabled pulse; pends forever if none is enabled.
    pub async fn next(&mut self) -> Tick {
        async fn maybe(i: &mut Option<Interval>) -> Instant {
            match i {
                Some(i) => i.tick().await,
                None => std::future::pending().await,
            }
        }
        let (tick, scheduled) = tokio::select! {
            at = maybe(&mut self.one_sec) => (Tick::OneSec, at),
            at = maybe(&mut self.slow) => (Tick::Slow, at),
            at = maybe(&mut self.fast) => (Tick::Fast, at),
        };
        let late = Instant::now().saturating_duration_since(scheduled);
        self.last_late = late;
        match tick {
            Tick::Fast => self.fast_jitter.record(late),
            Tick::Slow => self.slow_jitter.record(late),
            Tick::OneSec => self.one_sec_jitter.record(late),
        }
        tick
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meter_percentiles() {
        let mut m = JitterMeter::default();
        for us in [10u64, 20, 30, 40, 5000] {
            m.record(Duration::from_micros(us));
        }
        let s = m.stats();
        assert_eq!(s.ticks, 5);
        assert_eq!(s.max_us, 5000);
        assert!(s.p50_us >= 30 && s.p50_us <= 63, "{s:?}");
        assert_eq!(s.p99_us, 5000);
    }

    #[tokio::test(start_paused = true)]
    async fn pulses_fire_in_proportion() {
        let mut p = Pulses::new(TickConfig::default());
        let mut counts = [0u32; 3];
        let end = Instant::now() + Duration::from_millis(1005);
        while Instant::now() < end {
            match p.next().await {
                Tick::Fast => counts[0] += 1,
                Tick::Slow => counts[1] += 1,
                Tick::OneSec => counts[2] += 1,
            }
        }
        assert!((99..=101).contains(&counts[0]), "{counts:?}");
        assert_eq!(counts[1], 10);
        assert_eq!(counts[2], 1);
    }
}
