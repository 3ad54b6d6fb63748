//! Internal modules: async tasks inside the server that use the hub through
//! the same SDK as satellites, over an in-process link.
//!
//! A module gets a [`ModuleContext`]: a logged-in `flow::Client`, its JSON
//! parameters from `[modules.NAME]`, the pulses, a shutdown signal and a way to
//! report its own figures (shown at `/api/status`).

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;

use flow::tick::Tick;
use flow::transport::{Link, memory};
use flow::{Client, ConnectOptions};
use tokio::sync::{broadcast, watch};
use tokio::task::JoinHandle;
use tracing::{error, info};

use crate::net::serve_connection;
use crate::shared::Shared;

/// A boxed future returned by [`Module::run`].
pub type ModuleFuture = Pin<Box<dyn Future<Output = anyhow::Result<()>> + Send>>;

/// Something that runs inside the server on hub channels.
pub trait Module: Send + 'static {
    /// Short name: the login name and the `[modules.NAME]` section.
    fn name(&self) -> &'static str;
    /// Checks `[modules.NAME]` before anything starts, so that a bad value stops the server at start instead of
    /// failing the module later. Errors say `[modules.NAME] KEY: REASON`.
    fn check(&self, _params: &serde_json::Value) -> anyhow::Result<()> {
        Ok(())
    }
    /// Runs until `ctx.stopped()` resolves (return `Ok`) or a fatal error.
    fn run(self: Box<Self>, ctx: ModuleContext) -> ModuleFuture;
}

/// What a running module is given.
#[derive(Debug)]
pub struct ModuleContext {
    pub name: &'static str,
    pub client: Client,
    /// `[modules.NAME]` as JSON (an empty object when the section is absent).
    pub params: serde_json::Value,
    pub shutdown: watch::Receiver<bool>,
    shared: Arc<Shared>,
}

/// The server's shutdown signal as a module's helpers hold it ([`ModuleContext::stopping`]).
#[derive(Debug, Clone)]
pub struct Stopping(watch::Receiver<bool>);

impl Stopping {
    /// Resolves once the server stops its modules, exactly as [`ModuleContext::stopped`] does.
    pub async fn stopped(&mut self) {
        until_stopped(&mut self.0).await;
    }
}

/// Waits until the shutdown flag is set (or its sender is gone, which also means the server is stopping).
async fn until_stopped(shutdown: &mut watch::Receiver<bool>) {
    while !*shutdown.borrow() {
        if shutdown.changed().await.is_err() {
            return;
        }
    }
}

impl ModuleContext {
    /// The server's FastTick / SlowTick / OneSecTick pulses.
    pub fn ticks(&self) -> broadcast::Receiver<Tick> {
        self.shared.pulses.subscribe()
    }

    /// Publishes this module's figures at `/api/status`.
    pub fn report(&self, status: serde_json::Value) {
        self.shared.report(self.name, status);
    }

    /// Resolves when the server shuts down.
    pub async fn stopped(&mut self) {
        until_stopped(&mut self.shutdown).await;
    }

    /// The same signal for the module's own helpers, which cannot borrow the context: a module that hands its work
    /// to functions of its own gives them this, and they wait on [`Stopping::stopped`].
    pub fn stopping(&self) -> Stopping {
        Stopping(self.shutdown.clone())
    }

    /// The registry behind `/metrics`, where a module adds its own figures.
    pub fn metrics(&self) -> Arc<crate::metrics::Metrics> {
        self.shared.metrics.clone()
    }

    /// Where the module's spans go (docs/telemetry.md): a handle that records nothing when telemetry is off.
    pub fn telemetry(&self) -> flow_telemetry::Telemetry {
        self.shared.telemetry.clone()
    }

    /// The server's configuration (e.g. the data directory).
    pub fn config(&self) -> &crate::config::Config {
        &self.shared.config
    }
}

/// Connects a module to the hub over an in-process link and runs it.
pub async fn spawn(shared: Arc<Shared>, module: Box<dyn Module>) -> anyhow::Result<JoinHandle<()>> {
    let name = module.name();
    let (hub_end, module_end) = memory::pair(name);
    tokio::spawn(serve_connection(
        hub_end,
        shared.clone(),
        true,
        crate::admission::Stranger::trusted(),
    ));
    let opts = ConnectOptions::new(name, shared.tokens.admin());
    let client = Client::connect_link(Link::Memory(module_end), opts).await?;
    let ctx = ModuleContext {
        name,
        client,
        params: shared.config.module(name),
        shutdown: shared.modules_stop.subscribe(),
        shared: shared.clone(),
    };
    info!(module = name, "module started");
    Ok(tokio::spawn(async move {
        match module.run(ctx).await {
            Ok(()) => info!(module = name, "module stopped"),
            Err(e) => {
                error!(module = name, "module failed: {e:#}");
                shared.report(name, serde_json::json!({ "failed": format!("{e:#}") }));
            }
        }
    }))
}
