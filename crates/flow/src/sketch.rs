//! The sketch style of the paper's PySketch: a `setup` once, then a loop driven
//! by the pulses, on top of a [`Client`].

use std::future::Future;

use crate::client::{Client, ConnectOptions};
use crate::error::FlowError;
use crate::tick::{Pulses, Tick, TickConfig};
use crate::transport::FlowAddr;

/// A satellite written as setup + tick handlers.
pub trait Sketch: Send {
    /// Runs once after login: create channels, subscribe.
    fn setup(&mut self, client: &Client) -> impl Future<Output = Result<(), FlowError>> + Send;

    /// Runs on every enabled tick. Return an error to stop the sketch.
    fn tick(
        &mut self,
        client: &Client,
        tick: Tick,
    ) -> impl Future<Output = Result<(), FlowError>> + Send;
}

/// Connects, runs `setup`, then calls `tick` on each pulse until Ctrl-C or an error.
pub async fn run<S: Sketch>(
    addr: &FlowAddr,
    opts: ConnectOptions,
    ticks: TickConfig,
    mut sketch: S,
) -> Result<(), FlowError> {
    let client = Client::connect(addr, opts).await?;
    sketch.setup(&client).await?;
    let mut pulses = Pulses::new(ticks);
    loop {
        tokio::select! {
            tick = pulses.next() => sketch.tick(&client, tick).await?,
            _ = tokio::signal::ctrl_c() => break,
        }
    }
    client.close();
    Ok(())
}
