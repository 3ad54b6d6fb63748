//! What the example satellites share: the hub connection options, read the
//! same way as flowctl reads them (`--addr`, `--token`, `--data-dir`).

use std::path::PathBuf;

use anyhow::Context;
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
        let token = match &self.token {
            Some(t) => t.clone(),
            None => {
                let file = self.data_dir.join("token");
                std::fs::read_to_string(&file)
                    .with_context(|| {
                        format!(
                            "no token: pass --token or point --data-dir at the server's data ({})",
                            file.display()
                        )
                    })?
                    .trim()
                    .to_string()
            }
        };
        Ok((addr, ConnectOptions::new(name, token)))
    }
}
