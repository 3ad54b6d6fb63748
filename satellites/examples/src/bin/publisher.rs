//! Example publisher satellite, the Rust counterpart of the paper's
//! `publisher.py`: in `setup` it creates a streaming channel, and on every
//! SlowTick (100 ms) it publishes a small JSON message, but only while someone
//! subscribes (the hub tells the owner when the first subscriber arrives and
//! when the last one leaves).
//!
//! ```text
//! publisher --data-dir data --channel Example.counter
//! ```

use std::time::{SystemTime, UNIX_EPOCH};

use clap::Parser;
use flow::sketch::{self, Sketch};
use flow::tick::{Tick, TickConfig};
use flow::{Client, FlowError, Publisher};
use flow_examples::HubArgs;

/// Publishes a counter as JSON on a streaming channel while anyone listens.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    #[command(flatten)]
    hub: HubArgs,
    /// Channel to create.
    #[arg(long, default_value = "Example.counter")]
    channel: String,
}

/// The sketch: its channel and how many messages it has sent.
#[derive(Debug)]
struct CounterPublisher {
    channel: String,
    publisher: Option<Publisher>,
    count: u64,
}

impl Sketch for CounterPublisher {
    async fn setup(&mut self, client: &Client) -> Result<(), FlowError> {
        let header = r#"{"mime":"application/json","content":"counter"}"#;
        self.publisher = Some(client.publisher(&self.channel, header).await?);
        eprintln!("publisher: created {}", self.channel);
        Ok(())
    }

    async fn tick(&mut self, _client: &Client, tick: Tick) -> Result<(), FlowError> {
        let Some(publisher) = &self.publisher else {
            return Ok(());
        };
        // Nobody listening: producing would only cost CPU and bandwidth.
        if tick != Tick::Slow || !publisher.has_subscribers() {
            return Ok(());
        }
        self.count += 1;
        let ts_us = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_micros() as u64)
            .unwrap_or(0);
        let message = serde_json::json!({ "count": self.count, "ts_us": ts_us });
        match publisher.publish(message.to_string()).await {
            Ok(()) => Ok(()),
            // Between a lost connection and its restoration the channel has no
            // id; the SDK re-creates it, so skip this tick instead of stopping.
            Err(FlowError::NotReady(_)) => Ok(()),
            Err(e) => Err(e),
        }
    }
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let (addr, opts) = args.hub.connect_options("example-publisher")?;
    let ticks = TickConfig {
        fast: None,
        ..TickConfig::default()
    };
    let sketch = CounterPublisher {
        channel: args.channel,
        publisher: None,
        count: 0,
    };
    sketch::run(&addr, opts, ticks, sketch).await?;
    Ok(())
}
