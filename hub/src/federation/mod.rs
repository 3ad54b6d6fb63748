//! The federation: this hub on a Zenoh network (`[federation]`, off by default; docs/federation.md).
//!
//! It runs as a module: a client of its own hub over the in-process link, like any satellite. It **exports** the
//! local channels that match `export` (a liveliness token announces each, data goes out as Zenoh puts, services
//! answer Zenoh queries) and **imports** the remote channels that match `import` as local channels it owns. Data
//! crosses only while someone listens: a local subscriber of an import declares the Zenoh subscriber, which the
//! exporting hub's publisher sees as a match, which makes it subscribe on its own hub, which tells the producer.

mod export;
mod import;
pub mod keys;
mod link;
mod payload;
mod remote_error;
pub mod settings;
pub mod stamp;

use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use prometheus_client::metrics::counter::Counter;

use crate::config::Config;
use crate::module::{Module, ModuleContext, ModuleFuture};
use keys::Keys;
use link::{Counters, Link};

/// The federation module, with its Zenoh session opened at start (so that a bad endpoint stops the hub there).
pub struct Federation {
    session: zenoh::Session,
    keys: Keys,
    hub: String,
    export: Vec<glob::Pattern>,
    import: Vec<glob::Pattern>,
    call_timeout: Duration,
    queue: usize,
    lease: Duration,
}

impl std::fmt::Debug for Federation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Federation")
            .field("hub", &self.hub)
            .field("prefix", &self.keys.prefix())
            .finish_non_exhaustive()
    }
}

impl Federation {
    /// Opens the Zenoh session `[federation]` describes (the section was validated with the configuration).
    pub async fn open(config: &Config) -> anyhow::Result<Federation> {
        let f = &config.federation;
        let zconfig = settings::zenoh_config(f, &config.server.data_dir)?;
        let session = zenoh::open(zconfig).await.map_err(|e| {
            anyhow::anyhow!(
                "federation: opening the Zenoh session (listen {:?}, connect {:?}): {e}",
                f.listen,
                f.connect
            )
        })?;
        let globs = |list: &[String]| -> anyhow::Result<Vec<glob::Pattern>> {
            list.iter()
                .map(|p| glob::Pattern::new(p).with_context(|| format!("glob {p:?}")))
                .collect()
        };
        Ok(Federation {
            session,
            keys: Keys::new(&f.prefix)?,
            hub: f.hub_name(),
            export: globs(&f.export)?,
            import: globs(&f.import)?,
            call_timeout: Duration::from_millis(f.call_timeout_ms),
            queue: f.queue,
            lease: Duration::from_millis(f.lease_ms),
        })
    }
}

impl Module for Federation {
    fn name(&self) -> &'static str {
        "federation"
    }

    fn run(self: Box<Self>, mut ctx: ModuleContext) -> ModuleFuture {
        Box::pin(async move {
            let me = match ctx.client.session() {
                Some(s) => format!("federation#{}", s.conn),
                None => anyhow::bail!("the federation's link to its hub has no session"),
            };
            let link = Arc::new(Link {
                client: ctx.client.clone(),
                session: self.session.clone(),
                keys: self.keys.clone(),
                hub: self.hub.clone(),
                me,
                call_timeout: self.call_timeout,
                queue: self.queue,
                lease: self.lease,
                counters: Counters::register(&ctx.metrics()),
            });
            tracing::info!(
                hub = %link.hub,
                prefix = %link.keys.prefix(),
                zid = %self.session.zid(),
                "federation joined the Zenoh network"
            );
            let exporter = tokio::spawn(export::run(link.clone(), self.export.clone()));
            let importer = tokio::spawn(import::run(link.clone(), self.import.clone()));
            let mut report = tokio::time::interval(Duration::from_secs(1));
            loop {
                tokio::select! {
                    _ = ctx.stopped() => break,
                    _ = report.tick() => ctx.report(status(&link)),
                }
            }
            exporter.abort();
            importer.abort();
            let _ = exporter.await;
            let _ = importer.await;
            // Closing the session withdraws every token at once, so the other hubs drop this hub's channels now
            // rather than after the lease.
            if let Err(e) = self.session.close().await {
                tracing::warn!("federation: closing the Zenoh session: {e}");
            }
            Ok(())
        })
    }
}

fn status(link: &Link) -> serde_json::Value {
    let c = &link.counters;
    let get = |a: &Counter| a.get();
    serde_json::json!({
        "hub": link.hub,
        "zid": link.session.zid().to_string(),
        "sent": get(&c.sent),
        "received": get(&c.received),
        "lost_between_hubs": get(&c.lost_between_hubs),
        "dropped_here": get(&c.dropped_here),
        "calls_out": get(&c.calls_out),
        "calls_in": get(&c.calls_in),
        "exports": c.exports.get(),
        "imports": c.imports.get(),
    })
}
