//! What the export and import halves of the federation share: the link to the hub and to Zenoh, the figures,
//! and small helpers. A leaf: `mod.rs` builds a [`Link`], `export.rs` and `import.rs` use it.

use std::time::Duration;

use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;

use super::keys::Keys;

/// What the export and import halves share.
#[derive(Debug)]
pub(crate) struct Link {
    pub client: flow::Client,
    pub session: zenoh::Session,
    pub keys: Keys,
    /// This hub's name on the federation.
    pub hub: String,
    /// The owner label of this module's channels on the local hub (`federation#N`): its imports.
    pub me: String,
    pub call_timeout: Duration,
    pub queue: usize,
    pub lease: Duration,
    pub counters: Counters,
}

/// The federation's figures: at `/metrics` (`flow_federation_*`, docs/metrics.md) and at `/api/status` under
/// `federation`. Prometheus counters are atomics, so the Zenoh callbacks update them without a lock.
#[derive(Debug, Default)]
pub(crate) struct Counters {
    pub sent: Counter,
    pub received: Counter,
    /// Gaps in the origin hubs' sequences: messages lost between hubs (Zenoh's congestion control drops them).
    pub lost_between_hubs: Counter,
    /// Messages dropped from an import's queue because the local hub took them too slowly.
    pub dropped_here: Counter,
    pub calls_out: Counter,
    pub calls_in: Counter,
    pub exports: Gauge,
    pub imports: Gauge,
}

impl Counters {
    pub fn register(metrics: &crate::metrics::Metrics) -> Counters {
        let c = Counters::default();
        for (name, help, counter) in [
            (
                "flow_federation_sent_messages",
                "Stream messages this hub put on the Zenoh network",
                &c.sent,
            ),
            (
                "flow_federation_received_messages",
                "Stream messages from the Zenoh network published on this hub",
                &c.received,
            ),
            (
                "flow_federation_lost_between_hubs",
                "Messages missing in the origin hubs' sequences (dropped on the network)",
                &c.lost_between_hubs,
            ),
            (
                "flow_federation_dropped_here",
                "Messages dropped from an import's queue because this hub took them too slowly",
                &c.dropped_here,
            ),
            (
                "flow_federation_calls_out",
                "Calls of imported services sent to other hubs",
                &c.calls_out,
            ),
            (
                "flow_federation_calls_in",
                "Calls of exported services from other hubs",
                &c.calls_in,
            ),
        ] {
            metrics.register(name, help, counter.clone());
        }
        metrics.register(
            "flow_federation_exports",
            "Local channels this hub exports now",
            c.exports.clone(),
        );
        metrics.register(
            "flow_federation_imports",
            "Remote channels imported as local channels now",
            c.imports.clone(),
        );
        c
    }
}

/// Whether `name` matches any of `globs`.
pub(crate) fn selected(globs: &[glob::Pattern], name: &str) -> bool {
    globs.iter().any(|g| g.matches(name))
}

/// Locks a mutex, recovering the data if a panicking thread poisoned it: every map behind these locks is whole
/// after each statement.
pub(crate) fn lock<T>(m: &std::sync::Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// One unit of a gauge for as long as it lives (an export or import task, however it ends or is aborted).
pub(crate) struct Counted(Gauge);

impl Counted {
    pub fn new(gauge: &Gauge) -> Counted {
        gauge.inc();
        Counted(gauge.clone())
    }
}

impl Drop for Counted {
    fn drop(&mut self) {
        self.0.dec();
    }
}
