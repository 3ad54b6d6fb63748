//! `Service`: a service channel whose requests a Python handler answers, one at a time, on a thread that may take
//! the GIL (never on the connection's reader).

use std::sync::Mutex;

use bytes::Bytes;
use flow::ServiceCall;
use pyo3::prelude::*;
use tokio::task::JoinHandle;

use crate::message::Message;
use crate::payload::to_bytes;
use crate::runtime::runtime;

/// A service this client offers. It answers until `close()` or until the client closes, whether or not the
/// Python object is kept.
#[pyclass(frozen, module = "flow._native")]
#[derive(Debug)]
pub struct Service {
    name: String,
    task: Mutex<Option<JoinHandle<()>>>,
}

impl Service {
    pub fn start(py: Python<'_>, mut service: flow::Service, handler: Py<PyAny>) -> PyResult<Self> {
        let name = service.name().to_owned();
        // An `async def` handler runs on the loop that was running here, if one was.
        let event_loop: Option<Py<PyAny>> = py
            .import("asyncio")?
            .call_method0("get_running_loop")
            .ok()
            .map(Bound::unbind);
        let task_name = name.clone();
        let task = runtime().spawn(async move {
            while let Some(call) = service.next().await {
                let handler = Python::attach(|py| handler.clone_ref(py));
                let event_loop = Python::attach(|py| event_loop.as_ref().map(|l| l.clone_ref(py)));
                let name = task_name.clone();
                let payload = call.payload.clone();
                let answer = tokio::task::spawn_blocking(move || {
                    Python::attach(|py| answer(py, &name, &handler, event_loop.as_ref(), payload))
                })
                .await
                .unwrap_or_else(|e| Err(format!("the handler did not finish: {e}")));
                respond(call, answer).await;
            }
            // The channel goes when `service` drops here.
        });
        Ok(Service {
            name,
            task: Mutex::new(Some(task)),
        })
    }
}

async fn respond(call: ServiceCall, answer: Result<Bytes, String>) {
    // A caller that has gone (timed out) or a lost connection leave nobody to tell.
    let _ = call.respond(answer).await;
}

/// Runs the handler on one request; an exception becomes the error text the caller receives.
fn answer(
    py: Python<'_>,
    name: &str,
    handler: &Py<PyAny>,
    event_loop: Option<&Py<PyAny>>,
    payload: Bytes,
) -> Result<Bytes, String> {
    let run = || -> PyResult<Bytes> {
        let request = Message::new(name.to_owned(), 0, 0, 0, payload);
        let mut result = handler.call1(py, (request,))?.into_bound(py);
        let asyncio = py.import("asyncio")?;
        if py
            .import("inspect")?
            .call_method1("isawaitable", (&result,))?
            .is_truthy()?
        {
            result = match event_loop {
                Some(l) => asyncio
                    .call_method1("run_coroutine_threadsafe", (result, l))?
                    .call_method0("result")?,
                None => asyncio.call_method1("run", (result,))?,
            };
        }
        if result.is_none() {
            Ok(Bytes::new())
        } else {
            to_bytes(&result)
        }
    };
    run().map_err(|e| {
        let text = e.to_string();
        eprintln!("flow: service {name}: the handler raised {text}");
        text
    })
}

#[pymethods]
impl Service {
    /// The channel's name.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// Stops answering and removes the service; callers waiting get `ServiceGone`.
    fn close(&self) {
        if let Ok(mut task) = self.task.lock()
            && let Some(t) = task.take()
        {
            t.abort();
        }
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    #[pyo3(signature = (*_exc))]
    fn __exit__(&self, _exc: &Bound<'_, pyo3::types::PyTuple>) -> bool {
        self.close();
        false
    }

    fn __repr__(&self) -> String {
        format!("Service({:?})", self.name)
    }
}
