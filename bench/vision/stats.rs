//! Per-call timing samples and their summary figures.

use std::time::Instant;

/// Wall-clock and thread-CPU samples of one benchmark case, in milliseconds.
#[derive(Debug, Default, Clone)]
pub struct Samples {
    pub wall_ms: Vec<f64>,
    pub cpu_ms: Vec<f64>,
}

impl Samples {
    /// Times `work` once and records it.
    pub fn time<T>(&mut self, work: impl FnOnce() -> T) -> T {
        let cpu = cpu_time::ThreadTime::now();
        let wall = Instant::now();
        let result = work();
        self.wall_ms.push(wall.elapsed().as_secs_f64() * 1000.0);
        self.cpu_ms.push(cpu.elapsed().as_secs_f64() * 1000.0);
        result
    }

    pub fn extend(&mut self, other: &Samples) {
        self.wall_ms.extend_from_slice(&other.wall_ms);
        self.cpu_ms.extend_from_slice(&other.cpu_ms);
    }

    pub fn median(&self) -> f64 {
        percentile(&self.wall_ms, 0.5)
    }

    pub fn p95(&self) -> f64 {
        percentile(&self.wall_ms, 0.95)
    }

    pub fn cpu_median(&self) -> f64 {
        percentile(&self.cpu_ms, 0.5)
    }

    /// The mean CPU time: what a detector that works on some frames only (the network) costs per frame on average.
    pub fn cpu_mean(&self) -> f64 {
        self.cpu_ms.iter().sum::<f64>() / self.cpu_ms.len().max(1) as f64
    }
}

pub use vision_evaluation::evaluation::percentile;
