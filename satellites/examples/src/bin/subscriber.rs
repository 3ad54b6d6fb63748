//! Example subscriber satellite, the Rust counterpart of the paper's
//! `subscriber.py`: in `setup` it subscribes to a channel (which may not exist
//! yet: the subscription waits for it), and on every FastTick (10 ms) it prints
//! what has arrived, one line per message.
//!
//! ```text
//! subscriber --data-dir data --channel Example.counter [--count 10]
//! ```

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::Parser;
use flow::sketch::{self, Sketch};
use flow::tick::{Tick, TickConfig};
use flow::{Client, FlowError, Subscription};
use flow_examples::HubArgs;

/// Prints the messages of a streaming channel.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    #[command(flatten)]
    hub: HubArgs,
    /// Channel to subscribe to.
    #[arg(long, default_value = "Example.counter")]
    channel: String,
    /// Exit after this many messages.
    #[arg(long)]
    count: Option<u64>,
}

/// The sketch: its subscription and how many messages it has printed.
#[derive(Debug)]
struct Printer {
    channel: String,
    subscription: Option<Subscription>,
    printed: u64,
    limit: Option<u64>,
    /// Set when `limit` is reached; the sketch then stops by returning an error
    /// that `main` recognises as the normal end.
    finished: Arc<AtomicBool>,
}

impl Sketch for Printer {
    async fn setup(&mut self, client: &Client) -> Result<(), FlowError> {
        self.subscription = Some(client.subscribe(&self.channel).await?);
        eprintln!("subscriber: listening to {}", self.channel);
        Ok(())
    }

    async fn tick(&mut self, client: &Client, tick: Tick) -> Result<(), FlowError> {
        let Some(subscription) = &self.subscription else {
            return Ok(());
        };
        if tick != Tick::Fast {
            return Ok(());
        }
        let mut out = std::io::stdout().lock();
        while let Some(data) = subscription.try_recv() {
            let line = match std::str::from_utf8(&data.payload) {
                Ok(text) => text.to_string(),
                Err(_) => format!("<{} bytes> seq={}", data.payload.len(), data.seq),
            };
            if writeln!(out, "{line}").and_then(|()| out.flush()).is_err() {
                // Nobody reads our output any more (closed pipe): stop.
                return self.finish(client);
            }
            self.printed += 1;
            if self.limit.is_some_and(|limit| self.printed >= limit) {
                return self.finish(client);
            }
        }
        Ok(())
    }
}

impl Printer {
    fn finish(&self, client: &Client) -> Result<(), FlowError> {
        self.finished.store(true, Ordering::SeqCst);
        client.close();
        Err(FlowError::Closed)
    }
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let (addr, opts) = args.hub.connect_options("example-subscriber")?;
    let finished = Arc::new(AtomicBool::new(false));
    let sketch = Printer {
        channel: args.channel,
        subscription: None,
        printed: 0,
        limit: args.count,
        finished: finished.clone(),
    };
    let ticks = TickConfig {
        slow: None,
        one_sec: false,
        ..TickConfig::default()
    };
    match sketch::run(&addr, opts, ticks, sketch).await {
        Ok(()) => Ok(()),
        Err(FlowError::Closed) if finished.load(Ordering::SeqCst) => Ok(()),
        Err(e) => Err(e.into()),
    }
}
