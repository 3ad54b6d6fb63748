//! `Events`: what drives a `Sketch`, merged in Rust: the FastTick / SlowTick / OneSecTick pulses (tokio timers,
//! nothing spins) and the messages of its subscriptions, one at a time, with ticks first when both are due.

use std::sync::Arc;
use std::time::Duration;

use flow::tick::{JitterStats, Pulses, Tick, TickConfig};
use futures_util::future::select_all;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use tokio::sync::Mutex;

use crate::errors::ConnectionLost;
use crate::message::Message;
use crate::runtime::{seconds, wait};
use crate::subscription::{Feed, Subscription};

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
    pulses: Arc<Mutex<Pulses>>,
    feeds: Vec<Arc<Feed>>,
}

fn period(ms: Option<f64>) -> PyResult<Option<Duration>> {
    ms.map(|ms| seconds(ms / 1000.0))
        .transpose()
        .and_then(|d| match d {
            Some(d) if d.is_zero() => Err(pyo3::exceptions::PyValueError::new_err(
                "a tick period must be above zero (None turns the pulse off)",
            )),
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
        let config = TickConfig {
            fast: period(fast_ms)?,
            slow: period(slow_ms)?,
            one_sec,
        };
        // Timers belong to the runtime that will poll them.
        let pulses = {
            let _guard = crate::runtime::runtime().enter();
            Pulses::new(config)
        };
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

    /// Lateness of each pulse against its schedule so far, as measured by the timer (`fast`, `slow`, `one_sec`:
    /// ticks, mean_us, p50_us, p99_us, max_us).
    fn jitter<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let pulses = self.pulses.clone();
        let (fast, slow, one) = wait(py, async move {
            let p = pulses.lock().await;
            (
                p.fast_jitter.stats(),
                p.slow_jitter.stats(),
                p.one_sec_jitter.stats(),
            )
        })?;
        let d = PyDict::new(py);
        d.set_item("fast", stats(py, fast)?)?;
        d.set_item("slow", stats(py, slow)?)?;
        d.set_item("one_sec", stats(py, one)?)?;
        Ok(d)
    }
}
