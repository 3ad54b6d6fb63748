//! What the example satellites share: the hub connection options, read the
//! same way as flowctl reads them (`--addr`, `--token`, `--data-dir`).

use std::path::PathBuf;

use flow::token::{TokenKind, resolve_token};
use flow::{ConnectOptions, FlowAddr};

/// Where the hub is and how to log in.
#[derive(Debug, clap::Args)]
pub struct HubArgs {
    /// Hub address: tcp://HOST:PORT, unix:PATH or ws://HOST:PORT/flow.
    #[arg(long, env = "FLOW_ADDR", default_value = "tcp://127.0.0.1:9000")]
    pub addr: String,
    /// Login token; by default read from DATA_DIR/token.
    #[arg(long, env = "FLOW_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// The server's data directory, where the token file is.
    #[arg(long, env = "ROBOT_AGENT_DATA", default_value = "data")]
    pub data_dir: PathBuf,
}

impl HubArgs {
    /// The parsed address and login options for a satellite called `name`.
    /// Satellites reconnect by themselves, so the examples keep that on.
    pub fn connect_options(&self, name: &str) -> anyhow::Result<(FlowAddr, ConnectOptions)> {
        let addr: FlowAddr = self.addr.parse().map_err(anyhow::Error::msg)?;
        let token = resolve_token(self.token.as_deref(), &self.data_dir, TokenKind::User)?;
        Ok((addr, ConnectOptions::new(name, token)))
    }
}
