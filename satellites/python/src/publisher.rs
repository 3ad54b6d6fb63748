//! `Publisher`: the owner's side of a streaming channel, with the first/last-subscriber news the hub sends so that
//! a producer works only while someone listens.

use std::sync::{Arc, Mutex};

use pyo3::prelude::*;
use tokio::task::JoinHandle;

use crate::errors::{ChannelError, IntoPy};
use crate::loan::Loan;
use crate::payload::to_bytes;
use crate::runtime::{runtime, wait_for};

/// A streaming channel this client owns; `close()` (or dropping it) removes the channel.
#[pyclass(frozen, module = "flow._native")]
#[derive(Debug)]
pub struct Publisher {
    name: String,
    inner: Mutex<Option<Arc<flow::Publisher>>>,
    watcher: Option<JoinHandle<()>>,
}

impl Publisher {
    pub fn new(publisher: flow::Publisher, on_subscribers: Option<Py<PyAny>>) -> Self {
        let name = publisher.name().to_owned();
        let publisher = Arc::new(publisher);
        let watcher = on_subscribers.map(|callback| {
            let mut listening = publisher.subscribers();
            let name = name.clone();
            runtime().spawn(async move {
                // Reported from "nobody listens": a subscriber that was there before the channel existed makes it
                // start out listening, which the callback must hear too.
                let mut reported = false;
                loop {
                    let now = *listening.borrow_and_update();
                    if now != reported {
                        reported = now;
                        // The news arrives on the runtime; the callback runs where it may take the GIL without
                        // holding up the connection's reader.
                        let callback = Python::attach(|py| callback.clone_ref(py));
                        let name = name.clone();
                        let _ = tokio::task::spawn_blocking(move || {
                            Python::attach(|py| {
                                if let Err(e) = callback.call1(py, (now,)) {
                                    eprintln!("flow: on_subscribers callback of {name} failed:");
                                    e.print(py);
                                }
                            });
                        })
                        .await;
                    }
                    if listening.changed().await.is_err() {
                        break;
                    }
                }
            })
        });
        Publisher {
            name,
            inner: Mutex::new(Some(publisher)),
            watcher,
        }
    }

    fn publisher(&self) -> PyResult<Arc<flow::Publisher>> {
        self.inner
            .lock()
            .map_err(|_| ChannelError::new_err("publisher lock poisoned"))?
            .clone()
            .ok_or_else(|| {
                ChannelError::new_err(format!("{}: the publisher was closed", self.name))
            })
    }
}

#[pymethods]
impl Publisher {
    /// The channel's name.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// Publishes one message: bytes, str, a dict or list (as JSON), or a contiguous buffer such as a numpy array.
    /// Waits (with the GIL released) only while the connection's send queue is full.
    fn publish(&self, py: Python<'_>, payload: &Bound<'_, PyAny>) -> PyResult<()> {
        let bytes = to_bytes(payload)?;
        let publisher = self.publisher()?;
        // Almost always room: queue without a trip through the runtime.
        match publisher.try_publish(bytes.clone()) {
            Ok(true) => Ok(()),
            Ok(false) => crate::runtime::wait(py, publisher.publish(bytes))?.py_err(),
            Err(e) => Err(crate::errors::to_py(e)),
        }
    }

    /// A slot of the channel's shared-memory segment to write a message of up to `size` bytes into, in place
    /// (`loan.rs`): the zero-copy way to publish a large frame. None when the connection has no shared memory (not
    /// a Unix socket, or the hub's is off), when the channel's segment is not there yet (it is asked for now: the
    /// next call may have it), or when every slot is still held; then publish the frame with `publish`.
    fn loan(&self, size: usize) -> PyResult<Option<Loan>> {
        let publisher = self.publisher()?;
        // Asking the hub for the channel's segment is a task on the runtime.
        let _entered = runtime().enter();
        Ok(publisher
            .loan(size)
            .map(|loan| Loan::new(self.name.clone(), loan)))
    }

    /// Publishes unless the send queue is full; returns whether the message was queued (drops are counted in
    /// `skipped`).
    fn try_publish(&self, payload: &Bound<'_, PyAny>) -> PyResult<bool> {
        let bytes = to_bytes(payload)?;
        self.publisher()?.try_publish(bytes).py_err()
    }

    /// Messages `try_publish` dropped because the connection was saturated.
    #[getter]
    fn skipped(&self) -> PyResult<u64> {
        Ok(self.publisher()?.skipped())
    }

    /// Whether anyone subscribes now.
    #[getter]
    fn has_subscribers(&self) -> PyResult<bool> {
        Ok(self.publisher()?.has_subscribers())
    }

    /// Waits until someone subscribes; returns False if `timeout` (seconds) passes first.
    #[pyo3(signature = (timeout=None))]
    fn wait_subscribers(&self, py: Python<'_>, timeout: Option<f64>) -> PyResult<bool> {
        let mut listening = self.publisher()?.subscribers();
        let waited = wait_for(
            py,
            async move { listening.wait_for(|on| *on).await.is_ok() },
            timeout,
        )?;
        Ok(waited.unwrap_or(false))
    }

    /// Replaces the channel's header (dict or JSON text); every peer is told.
    fn set_header(&self, py: Python<'_>, header: &Bound<'_, PyAny>) -> PyResult<()> {
        let text = crate::header::header_text(Some(header))?;
        let publisher = self.publisher()?;
        crate::runtime::wait(py, async move { publisher.set_header(&text).await })?.py_err()
    }

    /// Removes the channel.
    fn close(&self) -> PyResult<()> {
        if let Some(w) = &self.watcher {
            w.abort();
        }
        let taken = self
            .inner
            .lock()
            .map_err(|_| ChannelError::new_err("publisher lock poisoned"))?
            .take();
        drop(taken);
        Ok(())
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    #[pyo3(signature = (*_exc))]
    fn __exit__(&self, _exc: &Bound<'_, pyo3::types::PyTuple>) -> PyResult<bool> {
        self.close()?;
        Ok(false)
    }

    fn __repr__(&self) -> String {
        format!("Publisher({:?})", self.name)
    }
}

impl Drop for Publisher {
    fn drop(&mut self) {
        if let Some(w) = &self.watcher {
            w.abort();
        }
    }
}
