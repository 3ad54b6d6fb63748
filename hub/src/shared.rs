//! The state every connection, module and HTTP handler shares. A leaf: it imports none of the files that use it
//! (`server.rs` builds it; `net/`, `http/` and `module.rs` read it).

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use tokio::sync::watch;

use crate::admission::Admission;
use crate::config::Config;
use crate::hub::Hub;
use crate::metrics::Metrics;
use crate::pairdb::PairDb;
use crate::pulse::PulseHub;
use crate::tokens::Tokens;

/// State shared by every connection, module and HTTP handler.
#[derive(Debug)]
pub struct Shared {
    pub config: Config,
    pub hub: Arc<Hub>,
    pub pairdb: Arc<PairDb>,
    pub tokens: Tokens,
    pub pulses: Arc<PulseHub>,
    /// What `/metrics` shows; modules register their own figures here.
    pub metrics: Arc<Metrics>,
    /// Connections that have not logged in yet, against `hub.max_unauthenticated`.
    pub admission: Arc<Admission>,
    /// Flips to true once at shutdown, after the modules have stopped; connections, listeners and pulses watch it.
    pub shutdown: watch::Sender<bool>,
    /// Flips to true first at shutdown: the modules' stop signal. They stop while the hub still serves them, so
    /// that one finishing its work (the recorder draining what the hub had accepted) still has its link.
    pub modules_stop: watch::Sender<bool>,
    /// Where modules' spans go (`[telemetry]`, docs/telemetry.md); off unless a collector is named.
    pub telemetry: flow_telemetry::Telemetry,
    pub(crate) reports: Mutex<BTreeMap<String, serde_json::Value>>,
}

impl Shared {
    /// Records a module's latest self-report (timings, counters), shown at `/api/status`.
    pub fn report(&self, module: &str, status: serde_json::Value) {
        self.reports
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .insert(module.to_string(), status);
    }

    pub fn module_reports(&self) -> BTreeMap<String, serde_json::Value> {
        self.reports
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }
}
