//! `Events`: what drives a `Sketch`, merged in Rust: the FastTick / SlowTick / OneSecTick pulses and the messages
//! of its subscriptions, one at a time, with ticks first when both are due.
//!
//! The pulses keep their own schedule rather than tokio intervals: tokio's timer counts whole milliseconds, so an
//! interval fires up to a millisecond after its deadline before any scheduling noise, which at 100 Hz is a tenth of
//! the period. Here the runtime's timer wakes the waiting Python thread [`EARLY`] before the deadline and the thread
//! sleeps the rest itself (a kernel sleep, accurate to tens of microseconds); nothing spins.

use std::sync::Arc;
use std::time::{Duration, Instant};

use flow::tick::{JitterMeter, JitterStats, Tick};
use futures_util::future::select_all;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use tokio::sync::Mutex;

use crate::errors::ConnectionLost;
use crate::message::Message;
use crate::runtime::{seconds, wait};
use crate::subscription::{Feed, Subscription};

/// How long before a pulse's deadline the runtime's (millisecond) timer wakes the thread that finishes the wait.
const EARLY: Duration = Duration::from_millis(2);
/// The longest tick period accepted: a year, far beyond any pulse, and far from overflowing the clock.
const MAX_PERIOD: Duration = Duration::from_secs(365 * 86_400);

/// One pulse: its period, its next deadline and how late it has fired.
#[derive(Debug)]
struct Lane {
    tick: Tick,
    period: Duration,
    next: Instant,
    late: JitterMeter,
}

/// The enabled pulses of one sketch.
#[derive(Debug, Default)]
struct Schedule {
    lanes: Vec<Lane>,
}

impl Schedule {
    fn new(periods: &[(Tick, Option<Duration>)]) -> Self {
        let start = Instant::now();
        Schedule {
            lanes: periods
                .iter()
                .filter_map(|&(tick, period)| {
                    period.map(|period| Lane {
                        tick,
                        period,
                        next: start + period,
                        late: JitterMeter::default(),
                    })
                })
                .collect(),
        }
    }

    /// Waits for the next deadline of any pulse and returns which fired; pends for ever with no pulse enabled.
    /// Dropped before it returns (a message came first), it has changed nothing.
    async fn next(&mut self) -> Tick {
        let Some((index, lane)) = self
            .lanes
            .iter()
            .enumerate()
            .min_by_key(|(_, l)| l.next)
            .map(|(i, l)| (i, l.next))
        else {
            return std::future::pending().await;
        };
        let coarse = lane.checked_sub(EARLY).unwrap_or(lane);
        tokio::time::sleep_until(tokio::time::Instant::from_std(coarse)).await;
        // This future runs on the Python thread that waits for it (`block_on`), never on a runtime worker, so
        // the thread may sleep the last stretch itself.
        let now = Instant::now();
        if lane > now {
            std::thread::sleep(lane - now);
        }
        self.lanes[index].fire(Instant::now())
    }

    fn stats(&self, tick: Tick) -> JitterStats {
        self.lanes
            .iter()
            .find(|l| l.tick == tick)
            .map(|l| l.late.stats())
            .unwrap_or_default()
    }
}

impl Lane {
    /// Records how late this pulse fired at `now` and moves its deadline on.
    fn fire(&mut self, now: Instant) -> Tick {
        self.late.record(now.saturating_duration_since(self.next));
        self.next += self.period;
        // A sketch that was busy past whole periods skips them rather than firing a burst (as tokio's `Skip`).
        if self.next <= now {
            let behind = now.duration_since(self.next).as_nanos() / self.period.as_nanos().max(1);
            let skip = u32::try_from(behind + 1).unwrap_or(u32::MAX);
            self.next += self.period * skip;
        }
        self.tick
    }
}

/// The next thing a sketch handles.
enum Event {
    Tick(Tick),
    Message(Message),
    Closed(String),
}

/// Pulses and subscriptions merged; `next()` returns `("fast" | "slow" | "one_sec", None)` or `("message", msg)`.
#[pyclass(frozen, module = "flow._native")]
#[derive(Debug)]
pub struct Events {
    pulses: Arc<Mutex<Schedule>>,
    feeds: Vec<Arc<Feed>>,
}

fn period(ms: Option<f64>) -> PyResult<Option<Duration>> {
    ms.map(|ms| seconds(ms / 1000.0))
        .transpose()
        .and_then(|d| match d {
            Some(d) if d.is_zero() => Err(pyo3::exceptions::PyValueError::new_err(
                "a tick period must be above zero (None turns the pulse off)",
            )),
            // A deadline is the clock plus the period: a period the clock cannot add is refused here rather
            // than overflowing there.
            Some(d) if d > MAX_PERIOD => Err(pyo3::exceptions::PyValueError::new_err(format!(
                "a tick period must be at most {} days (None turns the pulse off)",
                MAX_PERIOD.as_secs() / 86_400
            ))),
            d => Ok(d),
        })
}

async fn next_message(feeds: &[Arc<Feed>]) -> Event {
    if feeds.is_empty() {
        return std::future::pending().await;
    }
    // Every recv future is dropped except the winner's; a dropped one has taken nothing from its queue.
    let waits = feeds
        .iter()
        .map(|f| Box::pin(async move { (f.sub.recv().await, f) }));
    let ((data, feed), _, _) = select_all(waits).await;
    match data {
        Some(d) => Event::Message(feed.message(d)),
        None => Event::Closed(feed.sub.name().to_owned()),
    }
}

fn stats<'py>(py: Python<'py>, s: JitterStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("ticks", s.ticks)?;
    d.set_item("mean_us", s.mean_us)?;
    d.set_item("p50_us", s.p50_us)?;
    d.set_item("p99_us", s.p99_us)?;
    d.set_item("max_us", s.max_us)?;
    Ok(d)
}

#[pymethods]
impl Events {
    /// Pulses every `fast_ms` and `slow_ms` milliseconds (None: off) and each second if `one_sec`, merged with the
    /// messages of `subscriptions`.
    #[new]
    #[pyo3(signature = (subscriptions, fast_ms=Some(10.0), slow_ms=Some(100.0), one_sec=true))]
    fn new(
        subscriptions: Vec<PyRef<'_, Subscription>>,
        fast_ms: Option<f64>,
        slow_ms: Option<f64>,
        one_sec: bool,
    ) -> PyResult<Self> {
        let pulses = Schedule::new(&[
            (Tick::Fast, period(fast_ms)?),
            (Tick::Slow, period(slow_ms)?),
            (Tick::OneSec, one_sec.then_some(Duration::from_secs(1))),
        ]);
        Ok(Events {
            pulses: Arc::new(Mutex::new(pulses)),
            feeds: subscriptions.iter().map(|s| s.feed()).collect(),
        })
    }

    /// Waits (GIL released, Ctrl-C honoured) for the next pulse or message.
    fn next<'py>(&self, py: Python<'py>) -> PyResult<(&'static str, Option<Message>)> {
        let pulses = self.pulses.clone();
        let feeds = self.feeds.clone();
        let event = wait(py, async move {
            let mut pulses = pulses.lock().await;
            tokio::select! {
                biased;
                tick = pulses.next() => Event::Tick(tick),
                event = next_message(&feeds) => event,
            }
        })?;
        match event {
            Event::Tick(Tick::Fast) => Ok(("fast", None)),
            Event::Tick(Tick::Slow) => Ok(("slow", None)),
            Event::Tick(Tick::OneSec) => Ok(("one_sec", None)),
            Event::Message(m) => Ok(("message", Some(m))),
            Event::Closed(name) => Err(ConnectionLost::new_err(format!(
                "{name}: the client was closed"
            ))),
        }
    }

    /// Lateness of each pulse against its schedule so far, measured when the wait ends, before Python runs (`fast`, `slow`, `one_sec`:
    /// ticks, mean_us, p50_us, p99_us, max_us).
    fn jitter<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let pulses = self.pulses.clone();
        let (fast, slow, one) = wait(py, async move {
            let p = pulses.lock().await;
            (
                p.stats(Tick::Fast),
                p.stats(Tick::Slow),
                p.stats(Tick::OneSec),
            )
        })?;
        let d = PyDict::new(py);
        d.set_item("fast", stats(py, fast)?)?;
        d.set_item("slow", stats(py, slow)?)?;
        d.set_item("one_sec", stats(py, one)?)?;
        Ok(d)
    }
}
