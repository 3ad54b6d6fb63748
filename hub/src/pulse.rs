//! The server's pulses for internal modules: FastTick, SlowTick, OneSecTick.
//!
//! OneSecTick always runs (it also refreshes channel rates: one wake-up a
//! second). FastTick and SlowTick run only while some module listens, so an
//! idle server sleeps. Lateness of every tick is measured and exposed at
//! `/api/status` and, as a histogram, at `/metrics`.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use flow::tick::{JitterStats, Pulses, Tick, TickConfig};
use tokio::sync::{Notify, broadcast, watch};

use crate::hub::Hub;
use crate::metrics::{Metrics, PulseLabel};

/// Jitter of each pulse.
#[derive(Debug, Clone, Copy, Default)]
pub struct TickStats {
    pub fast: JitterStats,
    pub slow: JitterStats,
    pub one_sec: JitterStats,
}

/// Broadcasts ticks to listening modules.
#[derive(Debug)]
pub struct PulseHub {
    config: TickConfig,
    tx: broadcast::Sender<Tick>,
    listener_added: Notify,
    stats: Mutex<TickStats>,
}

impl PulseHub {
    pub fn new(fast: Duration, slow: Duration) -> Self {
        PulseHub {
            config: TickConfig {
                fast: Some(fast),
                slow: Some(slow),
                one_sec: true,
            },
            // A module that misses ticks sees `Lagged` and carries on; ticks are not data.
            tx: broadcast::channel(64).0,
            listener_added: Notify::new(),
            stats: Mutex::new(TickStats::default()),
        }
    }

    /// Receives every tick from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<Tick> {
        let rx = self.tx.subscribe();
        self.listener_added.notify_one();
        rx
    }

    pub fn stats(&self) -> TickStats {
        *self
            .stats
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Runs until shutdown.
    pub async fn run(
        self: Arc<Self>,
        hub: Arc<Hub>,
        metrics: Arc<Metrics>,
        mut shutdown: watch::Receiver<bool>,
    ) {
        let idle = TickConfig {
            fast: None,
            slow: None,
            one_sec: true,
        };
        let mut pulses = Pulses::new(idle);
        let mut full = false;
        loop {
            let want_full = self.tx.receiver_count() > 0;
            if want_full != full {
                let (fast, slow, one) = (
                    pulses.fast_jitter.clone(),
                    pulses.slow_jitter.clone(),
                    pulses.one_sec_jitter.clone(),
                );
                pulses = Pulses::new(if want_full { self.config } else { idle });
                (
                    pulses.fast_jitter,
                    pulses.slow_jitter,
                    pulses.one_sec_jitter,
                ) = (fast, slow, one);
                full = want_full;
            }
            tokio::select! {
                tick = pulses.next() => {
                    let pulse = match tick {
                        Tick::Fast => "fast",
                        Tick::Slow => "slow",
                        Tick::OneSec => "one_sec",
                    };
                    metrics
                        .tick_lateness
                        .get_or_create(&PulseLabel { pulse })
                        .observe(pulses.last_late.as_secs_f64());
                    if tick == Tick::OneSec {
                        hub.update_rates();
                        *self.stats.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = TickStats {
                            fast: pulses.fast_jitter.stats(),
                            slow: pulses.slow_jitter.stats(),
                            one_sec: pulses.one_sec_jitter.stats(),
                        };
                    }
                    // No receivers is fine: the next loop turn switches to idle.
                    let _ = self.tx.send(tick);
                }
                _ = self.listener_added.notified(), if !full => {}
                _ = shutdown.changed() => return,
            }
        }
    }
}
