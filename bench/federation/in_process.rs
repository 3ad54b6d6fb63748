//! Two federated hubs inside the benchmark's own process, as the plain Zenoh pair's two sessions are: what the
//! federation itself carries, without the satellites' socket hops on either side.
//!
//! The process benchmark (`links::Hubs`) runs the path a deployment has: a producer satellite's TCP hop into hub A,
//! hub A's Zenoh session, hub B's, and a reader satellite's TCP hop out of hub B, four processes' work on the
//! machine's cores. The Zenoh pair it is held against is two sessions in one process with a callback subscriber.
//! Here the producer and the reader are in-server modules of the two hubs (in-process links, as the agent's own
//! modules use), and both hubs run in this process, so the comparison is the federation against the engine alone.
//! Each hub runs on a tokio runtime of its own, as in its own process: on one shared runtime a producer flat out
//! starved the receiving hub's tasks in some runs (its import queue dropped nearly everything), which no deployment
//! of separate hubs does.

use std::time::Duration;

use anyhow::Context;
use flow_hub::module::{Module, ModuleContext, ModuleFuture};
use flow_hub::{Application, Config, RunningServer};
use tokio::sync::oneshot;

use agent_tests::free_port;

/// An in-server module that hands its logged-in client to the benchmark and then waits for the stop.
struct Handoff {
    name: &'static str,
    client: oneshot::Sender<flow::Client>,
}

impl Module for Handoff {
    fn name(&self) -> &'static str {
        self.name
    }

    fn run(self: Box<Self>, ctx: ModuleContext) -> ModuleFuture {
        Box::pin(async move {
            let mut ctx = ctx;
            // The benchmark may have gone already; then there is nobody to use the client.
            let _ = self.client.send(ctx.client.clone());
            ctx.stopped().await;
            Ok(())
        })
    }
}

/// One hub started in this process on a runtime of its own, as a `flow-hub` process has, with a `Handoff` module.
struct InProcessHub {
    runtime: tokio::runtime::Runtime,
    server: RunningServer,
}

impl InProcessHub {
    /// Starts the hub and returns it with the module's client.
    async fn start(
        dir: &tempfile::TempDir,
        module: &'static str,
        federation: &str,
        workers: Option<usize>,
    ) -> anyhow::Result<(InProcessHub, flow::Client)> {
        let toml = format!(
            "[server]\nhttp = \"127.0.0.1:0\"\nflow_tcp = \"\"\nflow_unix = \"\"\ndata_dir = {:?}\n\
             [hub]\nsubscriber_queue = 256\n[federation]\nenabled = true\nqueue = 256\n{federation}\n",
            dir.path().join("data"),
        );
        let path = dir.path().join("hub.toml");
        std::fs::write(&path, toml).context("writing the hub configuration")?;
        let config = Config::load(Some(&path)).map_err(|e| anyhow::anyhow!("{e}"))?;
        // Its own scheduler, as in its own process: two hubs on one runtime would compete for its workers, which
        // no deployment does. By default as many workers as `#[tokio::main]` gives `flow-hub` (one per core).
        let mut builder = tokio::runtime::Builder::new_multi_thread();
        if let Some(n) = workers {
            builder.worker_threads(n);
        }
        let runtime = builder
            .enable_all()
            .thread_name(module)
            .build()
            .context("starting the hub's runtime")?;
        let (tx, rx) = oneshot::channel();
        let app = Application {
            modules: vec![Box::new(Handoff {
                name: module,
                client: tx,
            })],
            ..Application::default()
        };
        let server = runtime.spawn(flow_hub::start(config, app)).await??;
        let client = tokio::time::timeout(agent_tests::PATIENCE, rx)
            .await
            .context("the module did not start")??;
        Ok((InProcessHub { runtime, server }, client))
    }

    /// Stops the hub on its runtime, then the runtime.
    async fn stop(self) {
        let InProcessHub { runtime, server } = self;
        let _ = runtime.spawn(server.shutdown()).await;
        runtime.shutdown_background();
    }
}

/// The JPEG flat out from an in-server producer on hub A to an in-server reader on hub B, both hubs in this
/// process, each on its own runtime with `workers` threads (`None`: one per core): messages per second delivered
/// on B.
pub async fn throughput(
    jpeg: &[u8],
    length: Duration,
    workers: Option<usize>,
) -> anyhow::Result<f64> {
    let (da, db) = (tempfile::tempdir()?, tempfile::tempdir()?);
    let port = free_port()?;
    let (a, producer) = InProcessHub::start(
        &da,
        "bench-producer",
        &format!("name = \"bench-a\"\nlisten = [\"tcp/127.0.0.1:{port}\"]\nexport = [\"Bench.*\"]"),
        workers,
    )
    .await?;
    let (b, reader) = InProcessHub::start(
        &db,
        "bench-reader",
        &format!(
            "name = \"bench-b\"\nconnect = [\"tcp/127.0.0.1:{port}\"]\nimport = [\"Bench.*\"]"
        ),
        workers,
    )
    .await?;
    let rate = crate::links::burst_rate(&producer, &reader, jpeg, length).await;
    drop((producer, reader));
    b.stop().await;
    a.stop().await;
    rate
}
