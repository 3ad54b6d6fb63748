//! The hub's log: on stderr (stdout carries only what the operator reads: the address to open) as every process of
//! the workspace logs (`flow::log`: plain lines unless on a terminal), with the WebSocket libraries capped below
//! trace, and federation peers that a hub refuses logged on that hub. Zenoh reports a failed handshake at debug only;
//! a small layer watches its accept side and says at WARN who was refused and why.

use std::time::Duration;

use flow::log::Throttle;
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::EnvFilter;
use tracing_subscriber::filter::Targets;
use tracing_subscriber::layer::{Context, Layer, SubscriberExt};
use tracing_subscriber::util::SubscriberInitExt;

/// Where Zenoh logs the failures of handshakes it accepted.
const ZENOH_ACCEPT: &str = "zenoh_transport::unicast::establishment::accept";
/// How often refusals are logged at most.
const REFUSALS_EVERY: Duration = Duration::from_secs(10);

/// Installs the log: `filter` for what is printed, and the refusal watcher beside it.
pub fn init(filter: EnvFilter) {
    let printed = flow::log::stderr().with_filter(quiet_frames(filter));
    let refusals =
        PeerRefusals::new().with_filter(Targets::new().with_target(ZENOH_ACCEPT, Level::DEBUG));
    tracing_subscriber::registry()
        .with(printed)
        .with(refusals)
        .init();
}

/// Caps the WebSocket libraries at debug level whatever the filter asks: at trace they print every frame's bytes,
/// the login frame with its token included.
fn quiet_frames(filter: EnvFilter) -> EnvFilter {
    ["tungstenite=debug", "tokio_tungstenite=debug"]
        .into_iter()
        .filter_map(|d| d.parse().ok())
        .fold(filter, EnvFilter::add_directive)
}

/// Turns Zenoh's debug report of a peer that failed user/password authentication into one WARN per interval.
#[derive(Debug)]
struct PeerRefusals {
    reports: Throttle,
}

impl PeerRefusals {
    fn new() -> Self {
        PeerRefusals {
            reports: Throttle::new(REFUSALS_EVERY),
        }
    }
}

/// An event's message, as text.
#[derive(Default)]
struct Message(String);

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}");
        }
    }

    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.0 = value.to_string();
        }
    }
}

/// What a refusal message says, or `None` for other handshake news.
fn refusal(message: &str) -> Option<&'static str> {
    if !message.contains("UsrPwd extension - Recv") {
        return None;
    }
    Some(if message.contains("Invalid password") {
        "a wrong password"
    } else if message.contains("Invalid user") {
        "a user [federation] users_file does not list"
    } else if message.contains("Expected extension") {
        "no user and password"
    } else {
        "credentials that do not decode"
    })
}

impl<S: Subscriber> Layer<S> for PeerRefusals {
    fn on_event(&self, event: &Event<'_>, _ctx: Context<'_, S>) {
        let mut message = Message::default();
        event.record(&mut message);
        let Some(why) = refusal(&message.0) else {
            return;
        };
        let Some(quiet) = self.reports.admit() else {
            return;
        };
        let quiet = quiet.0;
        tracing::warn!(
            target: "flow_hub::federation",
            "refused a federation peer that came with {why} (peers must match [federation] users_file; {quiet} more \
             refusals since the last report)"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zenoh_authentication_failures_are_told_apart() {
        assert_eq!(
            refusal("UsrPwd extension - Recv OpenSyn. Invalid password."),
            Some("a wrong password")
        );
        assert_eq!(
            refusal("UsrPwd extension - Recv InitSyn. Expected extension."),
            Some("no user and password")
        );
        assert_eq!(refusal("New transport link accepted"), None);
    }
}
