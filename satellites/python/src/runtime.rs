//! The process's one tokio runtime, and how Python threads wait on it: with the GIL released, and on the main
//! thread waking every [`SIGNAL_POLL`] to let Python run its signal handlers, so that Ctrl-C stops a blocked
//! `recv` or `call`.

use std::future::Future;
use std::sync::OnceLock;
use std::time::Duration;

use pyo3::prelude::*;
use tokio::runtime::Runtime;

/// How often a blocked wait takes the GIL back to check for signals: well inside the 100 ms a user may wait for
/// Ctrl-C to act, and rare enough to cost nothing measurable.
const SIGNAL_POLL: Duration = Duration::from_millis(40);

static RUNTIME: OnceLock<Runtime> = OnceLock::new();

/// The runtime every client of this process runs on: two workers, which is what a satellite needs (the reader and
/// writer of its connections) without taking cores from the robot.
pub fn runtime() -> &'static Runtime {
    // `start` ran when the module was imported; the module is not usable without it.
    RUNTIME
        .get()
        .unwrap_or_else(|| unreachable!("flow._native imported without its runtime"))
}

/// Starts the runtime and makes `asyncio` awaitables run on it; called once when the module loads, where a failure
/// is an `ImportError` rather than a panic later.
pub fn start() -> PyResult<()> {
    if RUNTIME.get().is_none() {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("flow-python")
            .enable_all()
            .build()
            .map_err(|e| {
                pyo3::exceptions::PyImportError::new_err(format!(
                    "flow: cannot start the tokio runtime: {e}"
                ))
            })?;
        // Another interpreter thread may have won the race; its runtime is as good as ours.
        let _ = RUNTIME.set(rt);
    }
    // Already initialised only when the module is loaded twice, which changes nothing.
    let _ = pyo3_async_runtimes::tokio::init_with_runtime(runtime());
    Ok(())
}

/// Runs `fut` to completion with the GIL released. On the main thread, where Python runs signal handlers, a
/// pending signal (Ctrl-C) is raised within [`SIGNAL_POLL`] as the exception its handler throws, and the future is
/// dropped, which cancels it; other threads never see signals and wait without waking.
pub fn wait<F>(py: Python<'_>, fut: F) -> PyResult<F::Output>
where
    F: Future + Send,
    F::Output: Send,
{
    if !on_main_thread(py) {
        return Ok(py.detach(|| runtime().block_on(fut)));
    }
    let mut fut = std::pin::pin!(fut);
    loop {
        let step = py.detach(|| {
            runtime().block_on(async { tokio::time::timeout(SIGNAL_POLL, fut.as_mut()).await })
        });
        match step {
            Ok(out) => return Ok(out),
            Err(_elapsed) => py.check_signals()?,
        }
    }
}

/// Whether this is the interpreter's main thread, the only one Python delivers signals to.
fn on_main_thread(py: Python<'_>) -> bool {
    let check = || -> PyResult<bool> {
        let threading = py.import("threading")?;
        let main = threading.call_method0("main_thread")?;
        let current = threading.call_method0("current_thread")?;
        Ok(main.is(&current))
    };
    // If Python cannot say, keep the signal checks: they are cheap and always correct.
    check().unwrap_or(true)
}

/// Like [`wait`], giving up after `timeout` (seconds; `None` waits for ever) with `Ok(None)`.
pub fn wait_for<F>(py: Python<'_>, fut: F, timeout: Option<f64>) -> PyResult<Option<F::Output>>
where
    F: Future + Send,
    F::Output: Send,
{
    match timeout {
        None => wait(py, fut).map(Some),
        Some(secs) => {
            let limit = seconds(secs)?;
            wait(py, async { tokio::time::timeout(limit, fut).await.ok() })
        }
    }
}

/// A timeout given in seconds, refused when negative or not a number.
pub fn seconds(secs: f64) -> PyResult<Duration> {
    Duration::try_from_secs_f64(secs).map_err(|_| {
        pyo3::exceptions::PyValueError::new_err(format!(
            "timeout must be a non-negative number of seconds, not {secs}"
        ))
    })
}
