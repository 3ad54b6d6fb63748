//! Lateness statistics of a replay: how far after its deadline each message was handed to the hub.

use std::time::Duration;

/// Every lateness of a replay, summarised at the end.
#[derive(Debug, Clone, Default)]
pub struct Lateness {
    samples_us: Vec<u64>,
}

/// p50, p99 and the maximum of a replay's lateness.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LatenessSummary {
    pub count: usize,
    pub p50: Duration,
    pub p99: Duration,
    pub max: Duration,
}

impl Lateness {
    pub fn record(&mut self, late: Duration) {
        self.samples_us
            .push(u64::try_from(late.as_micros()).unwrap_or(u64::MAX));
    }

    pub fn summary(&self) -> LatenessSummary {
        let mut sorted = self.samples_us.clone();
        sorted.sort_unstable();
        let at = |q: f64| {
            if sorted.is_empty() {
                return Duration::ZERO;
            }
            // Nearest rank: the smallest sample with at least q of all samples at or below it.
            let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
            Duration::from_micros(sorted[rank - 1])
        };
        LatenessSummary {
            count: sorted.len(),
            p50: at(0.5),
            p99: at(0.99),
            max: sorted
                .last()
                .map_or(Duration::ZERO, |m| Duration::from_micros(*m)),
        }
    }
}

impl std::fmt::Display for LatenessSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ms = |d: Duration| d.as_secs_f64() * 1000.0;
        write!(
            f,
            "lateness over {} messages: p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms",
            self.count,
            ms(self.p50),
            ms(self.p99),
            ms(self.max)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank_over_the_samples() {
        let mut l = Lateness::default();
        for us in 1..=100 {
            l.record(Duration::from_micros(us));
        }
        let s = l.summary();
        assert_eq!(s.count, 100);
        assert_eq!(s.p50, Duration::from_micros(50));
        assert_eq!(s.p99, Duration::from_micros(99));
        assert_eq!(s.max, Duration::from_micros(100));
        assert_eq!(Lateness::default().summary().max, Duration::ZERO);
    }
}
