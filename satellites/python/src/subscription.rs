//! `Subscription`: a sticky subscription by channel name, read as a blocking iterator, an async iterator or by
//! polling, from the Rust SDK's drop-oldest queue.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use flow::Data;
use pyo3::exceptions::{PyStopAsyncIteration, PyStopIteration};
use pyo3::prelude::*;

use crate::errors::{ConnectionLost, TimeoutError};
use crate::message::Message;
use crate::runtime::wait_for;

/// The state a subscription shares with the `Events` of a sketch.
#[derive(Debug)]
pub struct Feed {
    pub sub: flow::Subscription,
    last_seq: AtomicU64,
}

impl Feed {
    /// The Python message for `data`, with the gap since the previous one on this subscription.
    pub fn message(&self, data: Data) -> Message {
        let previous = self.last_seq.swap(data.seq, Ordering::Relaxed);
        // A seq at or below the previous one is a re-created channel starting again, not a loss.
        let gap = if previous != 0 && data.seq > previous {
            data.seq - previous - 1
        } else {
            0
        };
        Message::new(
            self.sub.name().to_owned(),
            data.seq,
            data.ts_us,
            gap,
            data.payload,
        )
    }
}

/// Messages of one channel, in order. Iterate (`for msg in sub`), `async for msg in sub`, or call `recv`.
#[pyclass(frozen, module = "flow._native")]
#[derive(Debug)]
pub struct Subscription {
    feed: Arc<Feed>,
}

impl Subscription {
    pub fn new(sub: flow::Subscription) -> Self {
        Subscription {
            feed: Arc::new(Feed {
                sub,
                last_seq: AtomicU64::new(0),
            }),
        }
    }

    pub fn feed(&self) -> Arc<Feed> {
        self.feed.clone()
    }

    fn closed(&self) -> PyErr {
        ConnectionLost::new_err(format!("{}: the client was closed", self.feed.sub.name()))
    }
}

#[pymethods]
impl Subscription {
    /// The channel's name.
    #[getter]
    fn name(&self) -> &str {
        self.feed.sub.name()
    }

    /// The next message. Raises `TimeoutError` if `timeout` seconds pass first and `ConnectionLost` once the
    /// client is closed. Ctrl-C interrupts the wait.
    #[pyo3(signature = (timeout=None))]
    fn recv(&self, py: Python<'_>, timeout: Option<f64>) -> PyResult<Message> {
        let feed = self.feed.clone();
        match wait_for(py, async move { feed.sub.recv().await }, timeout)? {
            Some(Some(data)) => Ok(self.feed.message(data)),
            Some(None) => Err(self.closed()),
            None => Err(TimeoutError::new_err(format!(
                "{}: no message within {} s",
                self.feed.sub.name(),
                timeout.unwrap_or_default()
            ))),
        }
    }

    /// The newest message, skipping older queued ones (for video: never build a backlog).
    #[pyo3(signature = (timeout=None))]
    fn recv_latest(&self, py: Python<'_>, timeout: Option<f64>) -> PyResult<Message> {
        let feed = self.feed.clone();
        match wait_for(py, async move { feed.sub.recv_latest().await }, timeout)? {
            Some(Some((data, _skipped))) => Ok(self.feed.message(data)),
            Some(None) => Err(self.closed()),
            None => Err(TimeoutError::new_err(format!(
                "{}: no message within {} s",
                self.feed.sub.name(),
                timeout.unwrap_or_default()
            ))),
        }
    }

    /// A queued message, or None, without waiting.
    fn try_recv(&self) -> Option<Message> {
        self.feed.sub.try_recv().map(|d| self.feed.message(d))
    }

    /// An awaitable of the next message, for asyncio code.
    fn recv_async<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let feed = self.feed.clone();
        pyo3_async_runtimes::tokio::future_into_py(py, async move {
            match feed.sub.recv().await {
                Some(data) => Ok(feed.message(data)),
                None => Err(ConnectionLost::new_err(format!(
                    "{}: the client was closed",
                    feed.sub.name()
                ))),
            }
        })
    }

    /// Messages this subscription dropped locally because its reader fell behind (drop-oldest).
    #[getter]
    fn dropped(&self) -> u64 {
        self.feed.sub.dropped()
    }

    /// The channel's header as of the last (re)subscription, as JSON text (None until the channel exists).
    #[getter]
    fn header(&self) -> Option<String> {
        self.feed.sub.info().map(|i| i.header)
    }

    fn __iter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    fn __next__(&self, py: Python<'_>) -> PyResult<Message> {
        let feed = self.feed.clone();
        match crate::runtime::wait(py, async move { feed.sub.recv().await })? {
            Some(data) => Ok(self.feed.message(data)),
            None => Err(PyStopIteration::new_err(())),
        }
    }

    fn __aiter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    fn __anext__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let feed = self.feed.clone();
        pyo3_async_runtimes::tokio::future_into_py(py, async move {
            match feed.sub.recv().await {
                Some(data) => Ok(feed.message(data)),
                None => Err(PyStopAsyncIteration::new_err(())),
            }
        })
    }

    fn __repr__(&self) -> String {
        format!("Subscription({:?})", self.feed.sub.name())
    }
}
