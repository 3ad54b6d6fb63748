//! Two federated hubs inside the benchmark's own process, as the plain Zenoh pair's two sessions are: what the
//! federation itself carries, without the satellites' socket hops on either side.
//!
//! The process benchmark (`links::Hubs`) runs the path a deployment has: a producer satellite's TCP hop into hub A,
//! hub A's Zenoh session, hub B's, and a reader satellite's TCP hop out of hub B, four processes' work on the
//! machine's cores. The Zenoh pair it is held against is two sessions in one process with a callback subscriber.
//! Here the producer and the reader are in-server modules of the two hubs (in-process links, as the agent's own
//! modules use), and both hubs run in this process, so the comparison is the federation against the engine alone.

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
            let mut stop = ctx.shutdown;
            // The benchmark may have gone already; then there is nobody to use the client.
            let _ = self.client.send(ctx.client);
            while !*stop.borrow() {
                if stop.changed().await.is_err() {
                    break;
                }
            }
            Ok(())
        })
    }
}

/// One hub started in this process with a `Handoff` module, and that module's client.
async fn hub(
    dir: &tempfile::TempDir,
    module: &'static str,
    federation: &str,
) -> anyhow::Result<(RunningServer, flow::Client)> {
    let toml = format!(
        "[server]\nhttp = \"127.0.0.1:0\"\nflow_tcp = \"\"\nflow_unix = \"\"\ndata_dir = {:?}\n\
         [hub]\nsubscriber_queue = 256\n[federation]\nenabled = true\nqueue = 256\n{federation}\n",
        dir.path().join("data"),
    );
    let path = dir.path().join("hub.toml");
    std::fs::write(&path, toml).context("writing the hub configuration")?;
    let config = Config::load(Some(&path)).map_err(|e| anyhow::anyhow!("{e}"))?;
    let (tx, rx) = oneshot::channel();
    let app = Application {
        modules: vec![Box::new(Handoff {
            name: module,
            client: tx,
        })],
        ..Application::default()
    };
    let server = flow_hub::start(config, app).await?;
    let client = tokio::time::timeout(agent_tests::PATIENCE, rx)
        .await
        .context("the module did not start")??;
    Ok((server, client))
}

/// The JPEG flat out from an in-server producer on hub A to an in-server reader on hub B, both hubs in this
/// process: messages per second delivered on B.
pub async fn throughput(jpeg: &[u8], length: Duration) -> anyhow::Result<f64> {
    let (da, db) = (tempfile::tempdir()?, tempfile::tempdir()?);
    let port = free_port()?;
    let (a, producer) = hub(
        &da,
        "bench-producer",
        &format!("name = \"bench-a\"\nlisten = [\"tcp/127.0.0.1:{port}\"]\nexport = [\"Bench.*\"]"),
    )
    .await?;
    let (b, reader) = hub(
        &db,
        "bench-reader",
        &format!(
            "name = \"bench-b\"\nconnect = [\"tcp/127.0.0.1:{port}\"]\nimport = [\"Bench.*\"]"
        ),
    )
    .await?;
    let rate = crate::links::burst_rate(&producer, &reader, jpeg, length).await;
    drop((producer, reader));
    b.shutdown().await;
    a.shutdown().await;
    rate
}
