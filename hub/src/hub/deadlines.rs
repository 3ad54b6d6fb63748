//! Service-call deadlines: one timer per hub instead of one sleeping task per call.
//!
//! Every pending call's deadline sits in an ordered set inside the hub's state, next to the call itself, so
//! answering a call removes its deadline under the same lock and leaves nothing behind. One task per hub sleeps
//! until the earliest deadline, fails whatever is due with `Timeout`, and sleeps again; with no call pending it
//! waits on a [`Notify`] and costs nothing. A call whose deadline is earlier than every other wakes it to sleep
//! less.
//!
//! The task holds the state only weakly and is aborted when the hub is dropped; it is started again by the next
//! call if the runtime it ran on has gone. It knows the hub's state only as a type and a function that fails what
//! is due, so that this file does not import the hub that uses it.

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex, Weak};
use std::time::{Duration, Instant};

use flow::protocol::CallId;
use tokio::sync::Notify;
use tokio::task::JoinHandle;

/// The longest a caller may ask to wait; longer requests are cut to this. Also keeps `Instant` arithmetic far from
/// overflow.
pub const MAX_CALL_TIMEOUT_MS: u32 = 600_000;

/// When each pending call gives up, earliest first. A `(deadline, call)` pair is unique because call ids are.
pub(super) type Deadlines = BTreeSet<(Instant, CallId)>;

/// The deadline of a call made at `now` that may wait `timeout_ms` (at least 1 ms, at most
/// [`MAX_CALL_TIMEOUT_MS`]); returns it with the timeout actually applied.
pub(super) fn deadline(now: Instant, timeout_ms: u32) -> (Instant, u32) {
    let ms = timeout_ms.clamp(1, MAX_CALL_TIMEOUT_MS);
    (now + Duration::from_millis(u64::from(ms)), ms)
}

/// The hub's one timer task and the bell that wakes it.
#[derive(Debug, Default)]
pub(super) struct CallTimer {
    bell: Arc<Notify>,
    task: Mutex<Option<JoinHandle<()>>>,
}

impl CallTimer {
    /// Tells the timer that the earliest deadline moved earlier, starting the timer task if none runs. Outside a
    /// Tokio runtime (the hub's synchronous unit tests) nothing is started: deadlines are then met only by
    /// explicit `Hub::expire_due` calls.
    pub(super) fn earlier<S: Send + 'static>(&self, state: &Arc<Mutex<S>>, expire: Expire<S>) {
        let mut task = self.task.lock().unwrap_or_else(|p| p.into_inner());
        // A task whose runtime shut down reports itself finished; the hub outlived it, so start another.
        if task.as_ref().is_none_or(JoinHandle::is_finished)
            && let Ok(runtime) = tokio::runtime::Handle::try_current()
        {
            *task = Some(runtime.spawn(run(Arc::downgrade(state), self.bell.clone(), expire)));
        }
        // A permit is stored if the task is not waiting right now, so this wake-up is never lost.
        self.bell.notify_one();
    }

    /// How many timer tasks this hub has running: 0 or 1.
    #[cfg(test)]
    pub(super) fn tasks(&self) -> usize {
        let task = self.task.lock().unwrap_or_else(|p| p.into_inner());
        usize::from(task.as_ref().is_some_and(|t| !t.is_finished()))
    }

    /// Stops the task: the hub is going away, and with it every call the task could expire.
    pub(super) fn stop(&self) {
        let mut task = self.task.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(t) = task.take() {
            t.abort();
        }
    }
}

/// Fails the calls of state `S` that are due at the given instant; returns the next deadline, if any.
pub(super) type Expire<S> = fn(&mut S, Instant) -> Option<Instant>;

/// The timer task: fail what is due, then sleep until the next deadline or until told of an earlier one.
async fn run<S>(state: Weak<Mutex<S>>, bell: Arc<Notify>, expire: Expire<S>) {
    loop {
        let next = {
            let Some(state) = state.upgrade() else {
                return;
            };
            // The state's own mutations keep it consistent across a panic, as the hub's lock helper assumes.
            let mut st = state.lock().unwrap_or_else(|p| p.into_inner());
            expire(&mut st, Instant::now())
        };
        match next {
            Some(at) => {
                tokio::select! {
                    () = bell.notified() => {}
                    () = tokio::time::sleep_until(at.into()) => {}
                }
            }
            None => bell.notified().await,
        }
    }
}
