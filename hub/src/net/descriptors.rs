//! File descriptors: the soft limit raised to the hard one at start, and what an accept loop does when the process
//! has none left. A listener that cannot accept backs off (doubling up to a second) and logs once per interval
//! instead of once per attempt; one descriptor is held in reserve and given up for a moment to accept and close
//! the connection at the head of the queue, so that a client waiting there is told at once instead of hanging.

use std::io;
use std::time::{Duration, Instant};

use rustix::process::{Resource, Rlimit, getrlimit, setrlimit};

/// How often a failing accept loop logs.
const LOG_EVERY: Duration = Duration::from_secs(10);
const FIRST_BACKOFF: Duration = Duration::from_millis(50);
const MAX_BACKOFF: Duration = Duration::from_secs(1);

/// Raises the soft limit on open descriptors to the hard limit; returns the limit in force afterwards.
pub fn raise_limit() -> Option<u64> {
    let limit = getrlimit(Resource::Nofile);
    let (Some(soft), hard) = (limit.current, limit.maximum) else {
        return None;
    };
    let wanted = hard.unwrap_or(soft);
    if wanted > soft {
        let raised = Rlimit {
            current: Some(wanted),
            maximum: hard,
        };
        if let Err(e) = setrlimit(Resource::Nofile, raised) {
            tracing::warn!("cannot raise the open-file limit from {soft} to {wanted}: {e}");
            return Some(soft);
        }
        tracing::debug!("open-file limit raised from {soft} to {wanted}");
    }
    Some(wanted)
}

/// The open-file limit in force now.
pub fn limit() -> Option<u64> {
    getrlimit(Resource::Nofile).current
}

/// Whether an accept error means the process or the system is out of descriptors.
pub fn out_of_descriptors(e: &io::Error) -> bool {
    matches!(
        e.raw_os_error(),
        Some(code) if code == rustix::io::Errno::MFILE.raw_os_error()
            || code == rustix::io::Errno::NFILE.raw_os_error()
    )
}

/// The state of one accept loop's failures: back-off, the log's interval and the reserve descriptor.
#[derive(Debug)]
pub struct AcceptFailures {
    what: &'static str,
    backoff: Duration,
    logged: Option<Instant>,
    quiet: u64,
    reserve: Option<std::fs::File>,
}

impl AcceptFailures {
    /// `what` names the listener in the log (`"http"`, `"tcp"`, `"unix"`).
    pub fn new(what: &'static str) -> Self {
        AcceptFailures {
            what,
            backoff: FIRST_BACKOFF,
            logged: None,
            quiet: 0,
            reserve: std::fs::File::open("/dev/null").ok(),
        }
    }

    /// An accept succeeded: the next failure starts the back-off over.
    pub fn succeeded(&mut self) {
        self.backoff = FIRST_BACKOFF;
    }

    /// An accept failed with `e`: logs (at most once per interval), and when out of descriptors, frees the reserve
    /// while `shed` accepts and drops one waiting connection. Then waits before the next attempt.
    pub async fn failed<F: Future<Output = ()>>(
        &mut self,
        e: &io::Error,
        shed: impl FnOnce() -> F,
    ) {
        let now = Instant::now();
        if self
            .logged
            .is_none_or(|t| now.duration_since(t) >= LOG_EVERY)
        {
            let limit = limit().map_or_else(|| "unknown".into(), |l| l.to_string());
            tracing::warn!(
                "{} accept failed: {e} (open-file limit {limit}); backing off ({} more since the last report)",
                self.what,
                self.quiet
            );
            self.logged = Some(now);
            self.quiet = 0;
        } else {
            self.quiet += 1;
        }
        if out_of_descriptors(e) && self.reserve.take().is_some() {
            shed().await;
            self.reserve = std::fs::File::open("/dev/null").ok();
        }
        tokio::time::sleep(self.backoff).await;
        self.backoff = (self.backoff * 2).min(MAX_BACKOFF);
    }
}
