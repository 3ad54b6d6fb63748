//! Logging that every process of the workspace shares: lines on stderr with colour codes only for a terminal (so that
//! a pipe, a file or the journal gets plain lines), and [`Throttle`], which holds a warning that repeats to one line
//! per interval with the count of those left out.
//!
//! The subscriber half (`stderr`, `init`) is behind the `logging` feature: a library that uses the SDK installs no
//! global log unless its binary asks for one. `Throttle` needs nothing but `std`.

use std::fmt;
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

#[cfg(feature = "logging")]
pub use printed::{init, stderr};

#[cfg(feature = "logging")]
mod printed {
    use std::io::IsTerminal;

    use tracing::Subscriber;
    use tracing_subscriber::EnvFilter;
    use tracing_subscriber::fmt::format::{DefaultFields, Format, Full};
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::registry::LookupSpan;
    use tracing_subscriber::util::SubscriberInitExt;

    /// The printed log as a layer: lines on stderr (stdout stays for what a program prints for its user), coloured
    /// only when stderr is a terminal and `NO_COLOR` is unset, so that `make run` into a file, a pipe or the journal
    /// gets plain lines that `grep` and `journalctl` read as written.
    pub fn stderr<S>()
    -> tracing_subscriber::fmt::Layer<S, DefaultFields, Format<Full>, fn() -> std::io::Stderr>
    where
        S: Subscriber + for<'a> LookupSpan<'a>,
    {
        let colour = std::io::stderr().is_terminal()
            && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty());
        tracing_subscriber::fmt::layer()
            .with_writer(std::io::stderr as fn() -> std::io::Stderr)
            .with_ansi(colour)
    }

    /// Installs [`stderr`] behind `filter` as the process's log. For a binary's `main`: it panics if a log is
    /// installed already, as `tracing_subscriber`'s own `init` does.
    pub fn init(filter: EnvFilter) {
        tracing_subscriber::registry()
            .with(filter)
            .with(stderr())
            .init();
    }
}

/// Holds a message that repeats (the same warning on every refused write of a full disk) to one per interval: the
/// first is logged at once, those that come within the interval after a logged one are only counted, and the first
/// after it is logged with that count.
#[derive(Debug)]
pub struct Throttle {
    interval: Duration,
    /// When the last message was logged, and how many have been left out since.
    last: Mutex<Option<(Instant, u64)>>,
}

impl Throttle {
    pub const fn new(interval: Duration) -> Self {
        Throttle {
            interval,
            last: Mutex::new(None),
        }
    }

    /// `Some` when the message is to be logged now, with the number left out since the last one logged; `None` when
    /// it is to be left out (and is counted).
    pub fn admit(&self) -> Option<LeftOut> {
        self.admit_at(Instant::now())
    }

    fn admit_at(&self, now: Instant) -> Option<LeftOut> {
        let mut last = self.last.lock().unwrap_or_else(PoisonError::into_inner);
        match &mut *last {
            Some((at, left_out)) if now.saturating_duration_since(*at) < self.interval => {
                *left_out += 1;
                None
            }
            slot => {
                let left_out = slot.as_ref().map_or(0, |&(_, n)| n);
                *slot = Some((now, 0));
                Some(LeftOut(left_out))
            }
        }
    }
}

/// How many messages a [`Throttle`] left out before the one it lets through. Displayed as a suffix for that
/// message: nothing when none were, else ` (N more like it since the last one logged)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LeftOut(pub u64);

impl fmt::Display for LeftOut {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            0 => Ok(()),
            n => write!(f, " ({n} more like it since the last one logged)"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINUTE: Duration = Duration::from_secs(60);

    #[test]
    fn the_first_message_is_logged_at_once() {
        let throttle = Throttle::new(MINUTE);
        assert_eq!(throttle.admit_at(Instant::now()), Some(LeftOut(0)));
    }

    #[test]
    fn messages_within_the_interval_are_counted_and_the_next_one_after_it_carries_the_count() {
        let throttle = Throttle::new(MINUTE);
        let start = Instant::now();
        assert!(throttle.admit_at(start).is_some());
        for s in 1..=5 {
            assert_eq!(throttle.admit_at(start + Duration::from_secs(s)), None);
        }
        assert_eq!(throttle.admit_at(start + MINUTE), Some(LeftOut(5)));
        // The count starts over, and so does the interval, from the message just logged.
        assert_eq!(
            throttle.admit_at(start + MINUTE + Duration::from_secs(1)),
            None
        );
        assert_eq!(throttle.admit_at(start + 2 * MINUTE), Some(LeftOut(1)));
    }

    #[test]
    fn a_message_after_a_quiet_interval_is_logged_without_a_count() {
        let throttle = Throttle::new(MINUTE);
        let start = Instant::now();
        assert!(throttle.admit_at(start).is_some());
        assert_eq!(throttle.admit_at(start + 10 * MINUTE), Some(LeftOut(0)));
    }

    #[test]
    fn the_count_reads_as_a_suffix_only_when_messages_were_left_out() {
        assert_eq!(LeftOut(0).to_string(), "");
        assert_eq!(
            LeftOut(3).to_string(),
            " (3 more like it since the last one logged)"
        );
    }
}
