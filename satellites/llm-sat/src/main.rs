//! `llm-sat`: the language-model satellite's command line. Loads the model before it connects, so that a missing or
//! broken model file fails at start naming the path (and the make target that provisions the default one).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use flow::token::{TokenKind, resolve_token};
use flow::{Client, ConnectOptions, FlowAddr};
use llm_sat::endpoint::{Endpoint, EndpointOptions, SchemaFormat};
use llm_sat::engine::{Engine, EngineOptions};
use llm_sat::generator::Generator;
use llm_sat::satellite::{self, Settings};
use llm_sat::turn::TurnLimits;

/// The model `make model-llm` provisions.
const DEFAULT_MODEL: &str = "models/llm/SmolLM2-135M-Instruct.Q4_1.gguf";

#[derive(Debug, clap::Parser)]
#[command(
    name = "llm-sat",
    about = "Serves the agent's chat turns (Agent.chat) with a language model"
)]
struct Args {
    /// Hub address: tcp://HOST:PORT, unix:PATH or ws://HOST:PORT/flow.
    #[arg(long, env = "FLOW_ADDR", default_value = "tcp://127.0.0.1:9000")]
    addr: String,
    /// Login token; by default read from DATA_DIR/token.
    #[arg(long, env = "FLOW_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// The server's data directory, where the token file is.
    #[arg(long, env = "ROBOT_AGENT_DATA", default_value = "data")]
    data_dir: PathBuf,
    /// Satellite name (login name); unique per hub. Default: llm-<pid>.
    #[arg(long)]
    name: Option<String>,
    /// A GGUF model file run in-process by llama.cpp.
    #[arg(long, default_value = DEFAULT_MODEL)]
    model: PathBuf,
    /// Stream replies from an OpenAI-compatible server instead (llama-server, Ollama, vLLM, llama-cpp-python):
    /// its base URL, e.g. http://gpu-box:8080/v1.
    #[arg(long, conflicts_with = "model")]
    endpoint: Option<String>,
    /// The model name sent to the endpoint.
    #[arg(long, default_value = "default")]
    endpoint_model: String,
    /// How the endpoint takes a JSON schema for tool calls: `json-object` (llama-server, llama-cpp-python) or
    /// `json-schema` (OpenAI, vLLM).
    #[arg(long, value_enum, default_value = "json-object")]
    schema_format: SchemaFormat,
    /// API key for the endpoint (sent as a bearer token).
    #[arg(long, env = "LLM_API_KEY", hide_env_values = true)]
    api_key: Option<String>,
    /// Threads for generation (default: the machine's cores).
    #[arg(long)]
    threads: Option<u32>,
    /// Tokens the context holds (prompt and reply).
    #[arg(long, default_value_t = 2048)]
    context: u32,
    /// 0 answers greedily (the same reply every time); above 0, sampling at that temperature.
    #[arg(long, default_value_t = 0.0)]
    temperature: f32,
    /// Sentences per reply at most.
    #[arg(long, default_value_t = 3)]
    max_sentences: u32,
    /// Tokens per reply at most.
    #[arg(long, default_value_t = 160)]
    max_tokens: u32,
    /// A free reply from the local model holds at least this many tokens (its end is masked until then): for tests
    /// and benches that interrupt or time a long generation. 0: the model ends when it likes.
    #[arg(long, default_value_t = 0)]
    min_tokens: u32,
    /// A reply ends after this many seconds, whatever it has said.
    #[arg(long, default_value_t = 15.0)]
    timeout_s: f64,
    /// Offer the rule program's tools on every turn (the model answers with a call or with words), not only on
    /// turns whose rule forces a tool. Small models call tools when they should not: off by default.
    #[arg(long)]
    offer_tools: bool,
    /// Export the spans of each turn's generation to an OpenTelemetry collector over OTLP/HTTP
    /// (e.g. http://127.0.0.1:4318); by default `OTEL_EXPORTER_OTLP_ENDPOINT` if set, else no telemetry
    /// (docs/telemetry.md).
    #[arg(long)]
    otlp: Option<String>,
}

fn main() -> anyhow::Result<()> {
    // Plain lines unless stderr is a terminal (a pipe or the journal), as every process of the workspace logs.
    flow::log::init(
        tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
    );
    let args = <Args as clap::Parser>::parse();
    let addr: FlowAddr = args.addr.parse().map_err(anyhow::Error::msg)?;
    let token = resolve_token(args.token.as_deref(), &args.data_dir, TokenKind::User)?;
    let name = args
        .name
        .clone()
        .unwrap_or_else(|| format!("llm-{}", std::process::id()));
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get() as u32));
    let generator: Box<dyn Generator> = match &args.endpoint {
        Some(url) => Box::new(Endpoint::new(EndpointOptions {
            url: url.clone(),
            model: args.endpoint_model.clone(),
            api_key: args.api_key.clone(),
            temperature: args.temperature,
            schema_format: args.schema_format,
        })),
        None => Box::new(
            Engine::load(
                &args.model,
                EngineOptions {
                    threads,
                    context: args.context,
                    temperature: args.temperature,
                    seed: 1,
                    min_tokens: args.min_tokens,
                },
            )
            .context("llm-sat cannot start")?,
        ),
    };
    let settings = Settings {
        name: name.clone(),
        limits: TurnLimits {
            max_sentences: args.max_sentences.max(1),
            max_tokens: args.max_tokens.max(1),
            timeout: Duration::from_secs_f64(args.timeout_s.max(0.1)),
            offer_tools: args.offer_tools,
        },
        telemetry: flow_telemetry::Telemetry::start(
            "llm-sat",
            args.otlp.as_deref().map(|url| ("--otlp", url)),
        )?,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()?;
    runtime.block_on(async move {
        let (stop_tx, stop) = tokio::sync::watch::channel(false);
        tokio::spawn(async move {
            shutdown_signal().await;
            let _ = stop_tx.send(true);
        });
        let opts = ConnectOptions::new(name.clone(), token);
        let client = Client::connect(&addr, opts)
            .await
            .with_context(|| format!("connecting to {addr}"))?;
        tracing::info!(%name, "llm satellite connected to {addr}");
        let result = satellite::run(client.clone(), generator, settings, stop).await;
        client.close();
        result
    })
}

/// Ctrl-C or SIGTERM.
async fn shutdown_signal() {
    let mut term = match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
        Ok(term) => term,
        Err(_) => return std::future::pending().await,
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {}
        _ = term.recv() => {}
    }
}
