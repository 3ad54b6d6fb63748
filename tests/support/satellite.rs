//! A real `whisper-sat` satellite for integration tests: started against a test server with the tiny.en model
//! (`make model`), killed on drop, ready once its presence channel exists (the model is loaded).

use std::time::Duration;

use anyhow::Context;
use tokio::process::Child;

use crate::agent::Agent;
use crate::binaries::command;

/// Loading the model and joining may take long on a machine busy building.
pub const SATELLITE_PATIENCE: Duration = Duration::from_secs(120);

/// A satellite process, killed (SIGKILL) on drop.
#[derive(Debug)]
pub struct Satellite {
    pub name: String,
    pub child: Child,
}

impl Satellite {
    /// Starts `whisper-sat run --name NAME` against `agent` and waits until it has joined.
    pub async fn start(agent: &Agent, name: &str) -> anyhow::Result<Satellite> {
        Self::start_with(agent, name, &[]).await
    }

    /// Starts `whisper-sat run --name NAME ARGS...` against `agent` and waits until it has joined.
    pub async fn start_with(agent: &Agent, name: &str, args: &[&str]) -> anyhow::Result<Satellite> {
        Self::start_with_env(agent, name, args, &[]).await
    }

    /// As [`Satellite::start_with`], with more environment variables.
    pub async fn start_with_env(
        agent: &Agent,
        name: &str,
        args: &[&str],
        env: &[(&str, &str)],
    ) -> anyhow::Result<Satellite> {
        let mut cmd = command("whisper-sat")?;
        cmd.arg("run")
            .arg("--addr")
            .arg(agent.tcp().to_string())
            .arg("--token")
            .arg(agent.token())
            .arg("--name")
            .arg(name)
            .args(args)
            .env(
                "RUST_LOG",
                std::env::var("AGENT_TEST_LOG").unwrap_or_else(|_| {
                    "info,whisper_rs=warn,whisper_rs::whisper_logging_hook=off".into()
                }),
            )
            .envs(env.iter().copied())
            .stdin(std::process::Stdio::null());
        let child = cmd.spawn().context("starting whisper-sat")?;
        let sat = Satellite {
            name: name.to_owned(),
            child,
        };
        wait_channel(agent, &format!("Agent.asr.sat.{name}")).await?;
        Ok(sat)
    }
}

/// Waits until a channel exists.
pub async fn wait_channel(agent: &Agent, name: &str) -> anyhow::Result<()> {
    let client = agent.client("test-channel-watch").await?;
    let mut events = client.events();
    let deadline = tokio::time::Instant::now() + SATELLITE_PATIENCE;
    loop {
        if client.channels().await?.iter().any(|c| c.name == name) {
            return Ok(());
        }
        tokio::select! {
            _ = events.recv() => {}
            () = tokio::time::sleep_until(deadline) => anyhow::bail!("channel {name} did not appear"),
        }
    }
}

/// The language model `make model-llm` provisions, the one `llm-sat` loads by default.
pub fn llm_model() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models/llm/SmolLM2-135M-Instruct.Q4_1.gguf")
}

/// A running `llm-sat`, killed (SIGKILL) on drop.
#[derive(Debug)]
pub struct LlmSat {
    pub child: Child,
}

impl LlmSat {
    /// `llm-sat ARGS...` on the default model, once `Agent.chat` exists.
    pub async fn start(agent: &Agent, args: &[&str]) -> anyhow::Result<LlmSat> {
        Self::start_with_env(agent, args, &[]).await
    }

    /// As [`LlmSat::start`], with more environment variables.
    pub async fn start_with_env(
        agent: &Agent,
        args: &[&str],
        env: &[(&str, &str)],
    ) -> anyhow::Result<LlmSat> {
        let model = llm_model();
        let mut all = vec![
            "--model",
            model.to_str().context("a model path that is not UTF-8")?,
        ];
        all.extend_from_slice(args);
        Self::start_bare(agent, &all, env).await
    }

    /// `llm-sat ARGS...` with no model chosen for it (`--endpoint`), once `Agent.chat` exists.
    pub async fn start_bare(
        agent: &Agent,
        args: &[&str],
        env: &[(&str, &str)],
    ) -> anyhow::Result<LlmSat> {
        let mut cmd = command("llm-sat")?;
        cmd.arg("--addr")
            .arg(agent.tcp().to_string())
            .arg("--token")
            .arg(agent.token())
            .args(args)
            .envs(env.iter().copied())
            .env("RUST_LOG", "info")
            .stdin(std::process::Stdio::null())
            .kill_on_drop(true);
        let child = cmd.spawn().context("starting llm-sat")?;
        wait_channel(agent, agent_contract::channels::CHAT.name).await?;
        Ok(LlmSat { child })
    }
}
