//! flowctl: the command-line client of the flow hub (list channels, watch,
//! publish files, WAV audio and JPEG sequences, call services, use the pair
//! database, record and replay MCAP files, watch rates). Errors are one line on
//! stderr and a non-zero exit.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use flow::token::{TokenKind, resolve_token};
use flow::{Client, ConnectOptions, FlowAddr};

mod commands;
mod duration;
mod hz;
mod record;
mod replay;
mod signals;
mod top;
mod wav;

/// Command-line client of the flow hub.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// Hub address: tcp://HOST:PORT, unix:PATH, ws://HOST:PORT/flow, serial:PATH?baud=N or udp://HOST:PORT.
    #[arg(
        long,
        env = "FLOW_ADDR",
        default_value = "tcp://127.0.0.1:9000",
        global = true
    )]
    addr: String,
    /// Login token; by default read from DATA_DIR/token.
    #[arg(long, env = "FLOW_TOKEN", global = true, hide_env_values = true)]
    token: Option<String>,
    /// The server's data directory, where the token file is.
    #[arg(long, env = "ROBOT_AGENT_DATA", default_value = "data", global = true)]
    data_dir: PathBuf,
    /// Use the admin token (DATA_DIR/admin.token) instead of the user token.
    #[arg(long, global = true)]
    admin: bool,
    /// Login name shown as the owner of channels this command creates.
    #[arg(long = "login", default_value = "flowctl", global = true)]
    login_name: String,
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// List channels with their properties and counters.
    Channels {
        #[arg(long)]
        json: bool,
    },
    /// Print messages of a channel, waiting for it to exist.
    Echo {
        name: String,
        /// Stop after this many messages.
        #[arg(long)]
        count: Option<u64>,
        /// One JSON object per message (seq, timestamp, size, payload if JSON).
        #[arg(long)]
        json: bool,
        /// Also write each message's payload to DIR/SEQ.bin (binary data such as JPEG or PCM, byte for byte).
        #[arg(long)]
        save: Option<PathBuf>,
    },
    /// Publish on a streaming channel (created if needed): stdin lines, a file, or a directory of files at a rate.
    Pub {
        name: String,
        #[arg(long, default_value = "{}")]
        header: String,
        /// Publish this file's bytes as one message.
        #[arg(long, conflicts_with = "dir")]
        file: Option<PathBuf>,
        /// Publish every file in this directory, in name order, as one message each.
        #[arg(long)]
        dir: Option<PathBuf>,
        /// Messages per second with --dir.
        #[arg(long, default_value_t = 15.0)]
        rate: f64,
        /// With --dir: go through the directory this many times.
        #[arg(long, default_value_t = 1)]
        repeat: u32,
        /// Wait until someone subscribes before publishing.
        #[arg(long)]
        wait_subscriber: bool,
    },
    /// Stream a WAV file as s16le mono 22050 Hz PCM (resampled and mixed down if needed).
    PubWav {
        name: String,
        file: PathBuf,
        #[arg(long, default_value_t = 20)]
        chunk_ms: u32,
        /// Pace chunks in real time instead of as fast as possible.
        #[arg(long)]
        realtime: bool,
        /// Append this much silence after the file (lets a VAD see the end of speech).
        #[arg(long, default_value_t = 0)]
        tail_ms: u32,
        /// Wait until someone subscribes before streaming.
        #[arg(long)]
        wait_subscriber: bool,
        /// Start streaming when the next message arrives on this channel, not at once: a microphone that hears a
        /// loudspeaker starts with what the loudspeaker plays (prints `waiting for CHANNEL` once subscribed).
        #[arg(long, value_name = "CHANNEL")]
        after: Option<String>,
    },
    /// Call a service with a JSON request and print the response.
    Call {
        name: String,
        json: String,
        #[arg(long, default_value_t = 10_000)]
        timeout_ms: u64,
    },
    /// Offer a service that answers every call with a fixed JSON reply (after --delay-ms), until Ctrl-C: a
    /// stand-in for a satellite that is not written yet, and a way to try a caller's timeouts.
    Serve {
        name: String,
        /// The reply, as JSON.
        #[arg(long, default_value = "{}")]
        reply: String,
        /// The service's header (JSON).
        #[arg(long, default_value = "{}")]
        header: String,
        /// Wait this long before answering each call.
        #[arg(long, default_value_t = 0)]
        delay_ms: u64,
    },
    /// Pair database commands.
    Db {
        /// Database to use (default: main).
        #[arg(long)]
        db: Option<String>,
        #[command(subcommand)]
        op: commands::DbOp,
    },
    /// Record channels into an MCAP file (Foxglove opens it) until Ctrl-C or --duration.
    Record(record::RecordArgs),
    /// Publish an MCAP recording again with its recorded timing.
    Replay(replay::ReplayArgs),
    /// A live table of channels: rates, subscribers, drops.
    Top(top::TopArgs),
    /// The rate and inter-arrival statistics of a channel, every second.
    Hz(hz::HzArgs),
}

#[tokio::main(flavor = "current_thread")]
async fn main() {
    let args = Args::parse();
    if let Err(e) = run(args).await {
        eprintln!("flowctl: {e:#}");
        std::process::exit(1);
    }
}

async fn run(args: Args) -> anyhow::Result<()> {
    let addr: FlowAddr = args.addr.parse().map_err(anyhow::Error::msg)?;
    let kind = if args.admin {
        TokenKind::Admin
    } else {
        TokenKind::User
    };
    let token = resolve_token(args.token.as_deref(), &args.data_dir, kind)?;
    let mut opts = ConnectOptions::new(args.login_name.clone(), token);
    opts.reconnect = false;
    opts.asynchronous = matches!(
        args.command,
        Cmd::Echo { .. }
            | Cmd::Pub { .. }
            | Cmd::PubWav { .. }
            | Cmd::Record(_)
            | Cmd::Replay(_)
            | Cmd::Hz(_)
            | Cmd::Serve { .. }
    );
    opts.queue = match args.command {
        Cmd::Record(_) => record::SUBSCRIPTION_QUEUE,
        _ => 1024,
    };
    let asynchronous = opts.asynchronous;
    let client = Client::connect(&addr, opts).await?;
    let result = dispatch(&client, args.command).await;
    if asynchronous {
        // Publishes return once queued: let the last ones reach the hub before the process exits.
        client
            .close_and_wait(std::time::Duration::from_secs(5))
            .await;
    } else {
        // Every request was answered; nothing is left to send.
        client.close();
    }
    result
}

async fn dispatch(client: &Client, cmd: Cmd) -> anyhow::Result<()> {
    match cmd {
        Cmd::Channels { json } => commands::channels(client, json).await,
        Cmd::Echo {
            name,
            count,
            json,
            save,
        } => commands::echo(client, &name, count, json, save.as_deref()).await,
        Cmd::Pub {
            name,
            header,
            file,
            dir,
            rate,
            repeat,
            wait_subscriber,
        } => {
            let publisher =
                commands::open_publisher(client, &name, &header, wait_subscriber).await?;
            match (file, dir) {
                (Some(file), _) => commands::pub_file(&publisher, &file).await?,
                (None, Some(dir)) => {
                    if !(rate > 0.0 && rate <= 10_000.0) {
                        bail!("--rate must be between 0 and 10000");
                    }
                    commands::pub_dir(&publisher, &dir, rate, repeat).await?
                }
                (None, None) => commands::pub_stdin(&publisher).await?,
            }
            // Everything sent before the ping's reply has reached the hub.
            client.ping().await?;
            Ok(())
        }
        Cmd::PubWav {
            name,
            file,
            chunk_ms,
            realtime,
            tail_ms,
            wait_subscriber,
            after,
        } => {
            if !(5..=1000).contains(&chunk_ms) {
                bail!("--chunk-ms must be between 5 and 1000");
            }
            let header = r#"{"mime":"audio/pcm","rate":22050,"channels":1,"format":"s16le"}"#;
            let publisher =
                commands::open_publisher(client, &name, header, wait_subscriber).await?;
            let pcm = wav::load_as_22050_mono(&file)?;
            if let Some(channel) = after {
                commands::wait_for_message(client, &channel).await?;
            }
            commands::pub_pcm(&publisher, &pcm, chunk_ms, realtime, tail_ms).await?;
            client.ping().await?;
            Ok(())
        }
        Cmd::Call {
            name,
            json,
            timeout_ms,
        } => {
            serde_json::from_str::<serde_json::Value>(&json)
                .context("the request is not valid JSON")?;
            let response = client
                .call(&name, json.into_bytes(), Duration::from_millis(timeout_ms))
                .await?;
            commands::print_payload(&response);
            Ok(())
        }
        Cmd::Serve {
            name,
            reply,
            header,
            delay_ms,
        } => {
            serde_json::from_str::<serde_json::Value>(&reply)
                .context("the reply is not valid JSON")?;
            commands::serve(
                client,
                &name,
                &header,
                reply,
                Duration::from_millis(delay_ms),
            )
            .await
        }
        Cmd::Db { db, op } => commands::db(client, db.as_deref(), op).await,
        Cmd::Record(args) => record::record(client, args).await,
        Cmd::Replay(args) => replay::replay(client, args).await,
        Cmd::Top(args) => top::top(client, args).await,
        Cmd::Hz(args) => hz::hz(client, args).await,
    }
}
