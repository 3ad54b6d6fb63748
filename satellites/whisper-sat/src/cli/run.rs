//! `whisper-sat run`: the ASR satellite on a flow hub.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use flow::token::{TokenKind, resolve_token};
use flow::{Client, ConnectOptions, FlowAddr};
use whisper_sat::recognition::RecognitionArgs;
use whisper_sat::satellite::{self, Settings};
use whisper_sat::transcriber::Transcriber;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Hub address: tcp://HOST:PORT, unix:PATH or ws://HOST:PORT/flow.
    #[arg(long, env = "FLOW_ADDR", default_value = "tcp://127.0.0.1:9000")]
    addr: String,
    /// Login token; by default read from DATA_DIR/token.
    #[arg(long, env = "FLOW_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// The server's data directory, where the token file is.
    #[arg(long, env = "ROBOT_AGENT_DATA", default_value = "data")]
    data_dir: PathBuf,
    /// Satellite name (login name and presence channel); unique per hub. Default: whisper-<pid>.
    #[arg(long)]
    name: Option<String>,
    /// Do not transcribe speculatively during the end-of-speech hangover: claim and decode an utterance only once
    /// it has ended (slower by up to the hangover less the post-roll; no decode is ever thrown away).
    #[arg(long)]
    no_speculate: bool,
    /// Do not judge the end of the turn from the transcript of a pause; end every utterance after the fixed
    /// hangover. By default a complete sentence ends after a short confirmation and a trailing-off one is held
    /// open (docs/asr.md, "End of turn"); the satellite that decodes a pause tells the others its verdict in the
    /// claim header, so all of them end the turn together. Satellites of one hub should agree on this flag.
    #[arg(long)]
    no_turn_detection: bool,
    /// Hold the agent's own voice, heard back through loudspeakers, under a floor learned from `Agent.speech`
    /// (docs/asr.md, "Own voice"). Off by default: the browser's echo canceller is on, and the floor makes
    /// satellites' segmentation depend on when the reference arrives.
    #[arg(long)]
    echo_gate: bool,
    /// Never take the transcript relay role (owning `Agent.transcript` and `Agent.asr.submit`). For a satellite on
    /// a hub that imports those channels from the microphone's hub over the federation (docs/federation.md): it
    /// then never races the import for them when its hub starts first.
    #[arg(long)]
    no_relay: bool,
    /// Export this satellite's spans of each turn to an OpenTelemetry collector over OTLP/HTTP
    /// (e.g. http://127.0.0.1:4318); by default `OTEL_EXPORTER_OTLP_ENDPOINT` if set, else no telemetry
    /// (docs/telemetry.md).
    #[arg(long)]
    otlp: Option<String>,
    #[command(flatten)]
    recognition: RecognitionArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let addr: FlowAddr = args.addr.parse().map_err(anyhow::Error::msg)?;
    let token = resolve_token(args.token.as_deref(), &args.data_dir, TokenKind::User)?;
    let name = args
        .name
        .clone()
        .unwrap_or_else(|| format!("whisper-{}", std::process::id()));
    let model = args.recognition.model();
    // Load the model before connecting, so a bad path fails at once with a clear message.
    let mut transcriber = Transcriber::load(&model, args.recognition.transcriber())?;
    if let Some(share) = args.recognition.core_share()? {
        tracing::info!(
            cores = share.cores(),
            satellites = share.members(),
            max_threads = transcriber.config().threads,
            "sharing this machine's cores with its other whisper satellites"
        );
        transcriber.share_cores(share);
    }
    let settings = Settings {
        name: name.clone(),
        segmenter: args.recognition.segmenter(),
        claim_retention: Duration::from_secs(30),
        speculate: !args.no_speculate,
        judge_turns: !args.no_speculate && !args.no_turn_detection,
        echo_gate: args.echo_gate,
        relay: !args.no_relay,
        telemetry: flow_telemetry::Telemetry::start(
            "whisper-sat",
            args.otlp.as_deref().map(|url| ("--otlp", url)),
        )?,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    runtime.block_on(async move {
        let opts = ConnectOptions::new(name.clone(), token);
        let client = Client::connect(&addr, opts)
            .await
            .with_context(|| format!("connecting to {addr}"))?;
        tracing::info!(%name, model = %model.display(), "whisper satellite connected to {addr}");
        let result = satellite::run(client.clone(), transcriber, settings).await;
        client.close();
        Ok(result?)
    })
}
