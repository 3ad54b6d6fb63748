//! `Client`: one hub connection, opened the way `flowctl` opens one (address, token or the token file in the data
//! directory), reconnecting by itself and restoring its channels and subscriptions, as the Rust SDK does.

use std::path::PathBuf;
use std::time::Duration;

use flow::token::{TokenKind, resolve_token};
use flow::{ConnectOptions, FlowAddr};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::database::Database;
use crate::errors::{AuthError, IntoPy};
use crate::header::header_text;
use crate::message::Message;
use crate::payload::to_bytes;
use crate::publisher::Publisher;
use crate::runtime::{runtime, seconds, wait};
use crate::service::Service;
use crate::subscription::Subscription;

/// The address used when neither `addr` nor `FLOW_ADDR` says otherwise: the agent's default TCP listener.
const DEFAULT_ADDR: &str = "tcp://127.0.0.1:9000";

/// A connection to a flow hub. Use it as a context manager, or call `close()`.
#[pyclass(frozen, module = "flow._native")]
#[derive(Debug)]
pub struct Client {
    client: flow::Client,
    name: String,
}

impl Client {
    pub fn inner(&self) -> &flow::Client {
        &self.client
    }
}

fn env(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.is_empty())
}

#[pymethods]
impl Client {
    /// Connects and logs in. `addr` defaults to `$FLOW_ADDR`, then tcp://127.0.0.1:9000; `token` to `$FLOW_TOKEN`,
    /// then the file `token` in `data_dir` (default `$ROBOT_AGENT_DATA`, then `data`), as `flowctl` reads it.
    #[staticmethod]
    #[pyo3(signature = (addr=None, token=None, data_dir=None, name=None, *, queue=64, reconnect=true, timeout=10.0))]
    #[allow(clippy::too_many_arguments)]
    fn connect(
        py: Python<'_>,
        addr: Option<String>,
        token: Option<String>,
        data_dir: Option<PathBuf>,
        name: Option<String>,
        queue: usize,
        reconnect: bool,
        timeout: f64,
    ) -> PyResult<Client> {
        let addr_text = addr
            .or_else(|| env("FLOW_ADDR"))
            .unwrap_or_else(|| DEFAULT_ADDR.to_owned());
        let addr: FlowAddr = addr_text
            .parse()
            .map_err(|e: String| PyValueError::new_err(format!("bad hub address: {e}")))?;
        let data_dir = data_dir
            .or_else(|| env("ROBOT_AGENT_DATA").map(PathBuf::from))
            .unwrap_or_else(|| PathBuf::from("data"));
        let token = token.or_else(|| env("FLOW_TOKEN"));
        let token = resolve_token(token.as_deref(), &data_dir, TokenKind::User)
            .map_err(|e| AuthError::new_err(e.to_string()))?;
        let name = match name {
            Some(n) => n,
            None => default_name(py),
        };
        let mut opts = ConnectOptions::new(name.clone(), token);
        opts.queue = queue.max(1);
        opts.reconnect = reconnect;
        opts.request_timeout = seconds(timeout)?;
        let client = wait(py, flow::Client::connect(&addr, opts))?.py_err()?;
        Ok(Client { client, name })
    }

    /// The login name, shown as the owner of this client's channels.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// Whether the connection is up now (it comes back by itself after a loss).
    #[getter]
    fn connected(&self) -> bool {
        *self.client.connection_state().borrow()
    }

    /// Creates a streaming channel this client publishes on. `on_subscribers(listening: bool)` is called, on a
    /// background thread, with True when the first subscriber arrives and False when the last one leaves.
    #[pyo3(signature = (name, header=None, on_subscribers=None))]
    fn publisher(
        &self,
        py: Python<'_>,
        name: &str,
        header: Option<&Bound<'_, PyAny>>,
        on_subscribers: Option<Py<PyAny>>,
    ) -> PyResult<Publisher> {
        let header = header_text(header)?;
        let publisher = wait(py, self.client.publisher(name, &header))?.py_err()?;
        Ok(Publisher::new(publisher, on_subscribers))
    }

    /// Subscribes to a channel by name; it need not exist yet, and the subscription survives reconnects.
    fn subscribe(&self, py: Python<'_>, name: &str) -> PyResult<Subscription> {
        let sub = wait(py, self.client.subscribe(name))?.py_err()?;
        Ok(Subscription::new(sub))
    }

    /// Offers a service. `handler(request: Message)` returns the answer (bytes, str, dict/list as JSON, or None
    /// for an empty one) or raises, which the caller sees as `ServiceFailed` with the exception's message. An
    /// `async def` handler runs on the event loop that was running when `serve` was called, else in `asyncio.run`.
    #[pyo3(signature = (name, handler, header=None))]
    fn serve(
        &self,
        py: Python<'_>,
        name: &str,
        handler: Py<PyAny>,
        header: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Service> {
        if !handler.bind(py).is_callable() {
            return Err(pyo3::exceptions::PyTypeError::new_err(
                "serve(name, handler): handler must be callable",
            ));
        }
        let header = header_text(header)?;
        let service = wait(py, self.client.serve(name, &header))?.py_err()?;
        Service::start(py, service, handler)
    }

    /// Calls a service and waits for its answer: `TimeoutError` after `timeout` seconds, `ServiceGone` if its
    /// owner leaves first, `ServiceFailed` if it answers with an error, `ChannelError` if there is no such service.
    #[pyo3(signature = (name, request, timeout=5.0))]
    fn call(
        &self,
        py: Python<'_>,
        name: &str,
        request: &Bound<'_, PyAny>,
        timeout: f64,
    ) -> PyResult<Message> {
        let payload = to_bytes(request)?;
        let limit = seconds(timeout)?;
        let answer = wait(py, self.client.call(name, payload, limit))?.py_err()?;
        Ok(Message::new(name.to_owned(), 0, 0, 0, answer))
    }

    /// `call` as an awaitable, for asyncio code.
    #[pyo3(signature = (name, request, timeout=5.0))]
    fn call_async<'py>(
        &self,
        py: Python<'py>,
        name: &str,
        request: &Bound<'py, PyAny>,
        timeout: f64,
    ) -> PyResult<Bound<'py, PyAny>> {
        let payload = to_bytes(request)?;
        let limit = seconds(timeout)?;
        let client = self.client.clone();
        let name = name.to_owned();
        pyo3_async_runtimes::tokio::future_into_py(py, async move {
            let answer = client.call(&name, payload, limit).await.py_err()?;
            Ok(Message::new(name, 0, 0, 0, answer))
        })
    }

    /// The pair database of this connection.
    #[getter]
    fn db(&self) -> Database {
        Database::new(self.client.clone())
    }

    /// Every channel on the hub: name, kind, owner, header and counters, as dicts.
    fn channels<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let list = wait(py, self.client.channels())?.py_err()?;
        list.into_iter()
            .map(|c| {
                let d = PyDict::new(py);
                d.set_item("id", c.id)?;
                d.set_item("name", c.name)?;
                d.set_item(
                    "kind",
                    match c.kind {
                        flow::ChannelKind::Stream => "stream",
                        flow::ChannelKind::Service => "service",
                    },
                )?;
                d.set_item("owner", c.owner)?;
                d.set_item("header", c.header)?;
                d.set_item("subscribers", c.stats.subscribers)?;
                d.set_item("messages", c.stats.msgs)?;
                d.set_item("messages_per_s", c.stats.msgs_per_s)?;
                d.set_item("bytes", c.stats.bytes)?;
                d.set_item("dropped", c.stats.dropped)?;
                Ok(d)
            })
            .collect()
    }

    /// A round trip to the hub.
    fn ping(&self, py: Python<'_>) -> PyResult<()> {
        wait(py, self.client.ping())?.py_err()
    }

    /// Closes the connection for good, after sending what is queued (waiting at most a second).
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        let client = self.client.clone();
        py.detach(|| {
            runtime().block_on(client.close_and_wait(Duration::from_secs(1)));
        });
        Ok(())
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    #[pyo3(signature = (*_exc))]
    fn __exit__(&self, py: Python<'_>, _exc: &Bound<'_, pyo3::types::PyTuple>) -> PyResult<bool> {
        self.close(py)?;
        Ok(false)
    }

    fn __repr__(&self) -> String {
        format!(
            "Client(name={:?}, connected={})",
            self.name,
            self.connected()
        )
    }
}

/// The script's file name without `.py`, so `ps` and `flowctl channels` show who owns what.
fn default_name(py: Python<'_>) -> String {
    let argv0: Option<String> = py
        .import("sys")
        .and_then(|sys| sys.getattr("argv"))
        .and_then(|argv| argv.get_item(0))
        .and_then(|a| a.extract())
        .ok();
    argv0
        .as_deref()
        .and_then(|p| std::path::Path::new(p).file_stem())
        .and_then(|s| s.to_str())
        .filter(|s| !s.is_empty() && *s != "-c")
        .map_or_else(|| "python".to_owned(), |s| format!("py-{s}"))
}
