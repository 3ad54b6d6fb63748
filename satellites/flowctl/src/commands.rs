//! The flowctl subcommands.

use clap::Subcommand;
use std::io::Write;
use std::path::Path;
use std::time::Duration;

use anyhow::{Context, bail};
use bytes::Bytes;
use flow::{Client, ErrorCode, FlowError, Publisher};
use tokio::io::AsyncBufReadExt;
use tokio::time::Instant;

use crate::wav::RATE;

/// `flowctl db`: the pair-database operations.
#[derive(Debug, Subcommand)]
pub enum DbOp {
    /// List the variables of the database.
    List,
    Get {
        key: String,
    },
    Set {
        key: String,
        json: String,
    },
    Del {
        key: String,
    },
    /// List the databases.
    Dbs,
    Create {
        name: String,
    },
    Drop {
        name: String,
    },
}

pub async fn channels(client: &Client, json: bool) -> anyhow::Result<()> {
    let list = client.channels().await?;
    let mut out = std::io::stdout().lock();
    if json {
        let rows: Vec<_> = list
            .iter()
            .map(|c| {
                serde_json::json!({
                    "id": c.id, "name": c.name, "hash": format!("{:016x}", c.hash), "kind": c.kind.as_str(),
                    "owner": c.owner, "subscribers": c.stats.subscribers,
                    "header": serde_json::from_str::<serde_json::Value>(&c.header).unwrap_or_default(),
                    "msgs": c.stats.msgs, "bytes": c.stats.bytes, "dropped": c.stats.dropped,
                    "msgs_per_s": c.stats.msgs_per_s, "bytes_per_s": c.stats.bytes_per_s,
                })
            })
            .collect();
        writeln!(out, "{}", serde_json::Value::Array(rows))?;
        return Ok(());
    }
    writeln!(
        out,
        "{:>5}  {:<7}  {:<24} {:<20} {:>4} {:>8} {:>10} {:>8}",
        "ID", "KIND", "NAME", "OWNER", "SUBS", "MSG/S", "BYTES/S", "DROPPED"
    )?;
    for c in list {
        writeln!(
            out,
            "{:>5}  {:<7}  {:<24} {:<20} {:>4} {:>8.1} {:>10.0} {:>8}",
            c.id,
            c.kind.as_str(),
            c.name,
            c.owner,
            c.stats.subscribers,
            c.stats.msgs_per_s,
            c.stats.bytes_per_s,
            c.stats.dropped
        )?;
    }
    Ok(())
}

pub async fn echo(
    client: &Client,
    name: &str,
    count: Option<u64>,
    json: bool,
    save: Option<&std::path::Path>,
) -> anyhow::Result<()> {
    if let Some(dir) = save {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let sub = client.subscribe(name).await?;
    let mut seen = 0u64;
    let mut out = std::io::stdout();
    while count.is_none_or(|c| seen < c) {
        let Some(msg) = sub.recv().await else {
            bail!("connection closed")
        };
        seen += 1;
        if let Some(dir) = save {
            let path = dir.join(format!("{}.bin", msg.seq));
            std::fs::write(&path, &msg.payload)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        let text = std::str::from_utf8(&msg.payload)
            .ok()
            .filter(|t| serde_json::from_str::<serde_json::Value>(t).is_ok());
        let line = if json {
            serde_json::json!({
                "seq": msg.seq, "ts_us": msg.ts_us, "bytes": msg.payload.len(),
                "json": text.and_then(|t| serde_json::from_str::<serde_json::Value>(t).ok()),
            })
            .to_string()
        } else {
            // JSON and plain text print as they are; anything else as a size line.
            let plain = std::str::from_utf8(&msg.payload)
                .ok()
                .filter(|t| !t.chars().any(|c| c.is_control() && c != '\t'));
            match text.or(plain) {
                Some(t) => t.to_string(),
                None => format!(
                    "<{} bytes> seq={} ts_us={}",
                    msg.payload.len(),
                    msg.seq,
                    msg.ts_us
                ),
            }
        };
        // A closed pipe (e.g. `| head`) ends the command quietly.
        if writeln!(out, "{line}").and_then(|()| out.flush()).is_err() {
            return Ok(());
        }
    }
    Ok(())
}

pub async fn open_publisher(
    client: &Client,
    name: &str,
    header: &str,
    wait: bool,
) -> anyhow::Result<Publisher> {
    let publisher = match client.publisher(name, header).await {
        Err(FlowError::Hub(e)) if e.code == ErrorCode::Exists => {
            bail!("channel {name} already exists and belongs to someone else")
        }
        other => other?,
    };
    if wait {
        let mut subs = publisher.subscribers();
        subs.wait_for(|on| *on)
            .await
            .context("waiting for a subscriber")?;
    }
    Ok(publisher)
}

/// Subscribes to `channel`, says so on stdout (a caller may start the producer then), and returns when its next
/// message arrives.
pub async fn wait_for_message(client: &Client, channel: &str) -> anyhow::Result<()> {
    let subscription = client
        .subscribe(channel)
        .await
        .with_context(|| format!("subscribing to {channel}"))?;
    println!("waiting for {channel}");
    std::io::Write::flush(&mut std::io::stdout()).context("writing to stdout")?;
    subscription
        .recv()
        .await
        .with_context(|| format!("{channel} ended before its first message"))?;
    Ok(())
}

pub async fn pub_file(publisher: &Publisher, file: &Path) -> anyhow::Result<()> {
    let data = tokio::fs::read(file)
        .await
        .with_context(|| format!("reading {}", file.display()))?;
    publisher.publish(data).await?;
    Ok(())
}

pub async fn pub_stdin(publisher: &Publisher) -> anyhow::Result<()> {
    let mut lines = tokio::io::BufReader::new(tokio::io::stdin()).lines();
    while let Some(line) = lines.next_line().await? {
        publisher.publish(line.into_bytes()).await?;
    }
    Ok(())
}

pub async fn pub_dir(
    publisher: &Publisher,
    dir: &Path,
    rate: f64,
    repeat: u32,
) -> anyhow::Result<()> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("{} has no files", dir.display());
    }
    let mut frames = Vec::with_capacity(files.len());
    for f in &files {
        frames.push(Bytes::from(
            std::fs::read(f).with_context(|| format!("reading {}", f.display()))?,
        ));
    }
    let period = Duration::from_secs_f64(1.0 / rate);
    let start = Instant::now();
    let mut n = 0u32;
    for _ in 0..repeat {
        for frame in &frames {
            // Absolute schedule: no drift from the time each publish takes.
            tokio::time::sleep_until(start + period * n).await;
            publisher.publish(frame.clone()).await?;
            n += 1;
        }
    }
    Ok(())
}

pub async fn pub_pcm(
    publisher: &Publisher,
    pcm: &[i16],
    chunk_ms: u32,
    realtime: bool,
    tail_ms: u32,
) -> anyhow::Result<()> {
    let chunk = (RATE * chunk_ms / 1000) as usize;
    let tail = vec![0i16; (RATE * tail_ms / 1000) as usize];
    let all: Vec<i16> = pcm.iter().copied().chain(tail).collect();
    let period = Duration::from_millis(u64::from(chunk_ms));
    let start = Instant::now();
    for (n, samples) in all.chunks(chunk).enumerate() {
        if realtime {
            tokio::time::sleep_until(start + period * n as u32).await;
        }
        let bytes: Vec<u8> = samples.iter().flat_map(|s| s.to_le_bytes()).collect();
        publisher.publish(bytes).await?;
    }
    Ok(())
}

pub fn print_payload(payload: &[u8]) {
    match std::str::from_utf8(payload) {
        Ok(text) => println!("{text}"),
        Err(_) => println!("<{} bytes>", payload.len()),
    }
}

pub async fn db(client: &Client, db: Option<&str>, op: DbOp) -> anyhow::Result<()> {
    if let Some(name) = db {
        client.db_select(name).await?;
    }
    match op {
        DbOp::List => {
            for key in client.var_list().await? {
                println!("{key}");
            }
        }
        DbOp::Get { key } => match client.var_get(&key).await? {
            Some(v) => println!("{v}"),
            None => bail!("no variable {key}"),
        },
        DbOp::Set { key, json } => {
            let value: serde_json::Value =
                serde_json::from_str(&json).context("the value is not valid JSON")?;
            client.var_set(&key, &value).await?;
        }
        DbOp::Del { key } => client.var_del(&key).await?,
        DbOp::Dbs => {
            for name in client.db_list().await? {
                println!("{name}");
            }
        }
        DbOp::Create { name } => client.db_create(&name).await?,
        DbOp::Drop { name } => client.db_remove(&name).await?,
    }
    Ok(())
}

/// `flowctl serve`: answers each call on `name` with `reply` after `delay`, until Ctrl-C or SIGTERM. Calls are
/// answered one at a time, in order, as a simple satellite would; "serving NAME" on stderr says it is offered.
pub async fn serve(
    client: &Client,
    name: &str,
    header: &str,
    reply: String,
    delay: Duration,
) -> anyhow::Result<()> {
    let mut service = client
        .serve(name, header)
        .await
        .with_context(|| format!("offering {name}"))?;
    eprintln!("serving {name}");
    let reply = Bytes::from(reply);
    let answer = async {
        while let Some(call) = service.next().await {
            tokio::time::sleep(delay).await;
            call.respond(Ok(reply.clone())).await?;
        }
        anyhow::Ok(())
    };
    tokio::select! {
        r = answer => r,
        r = crate::signals::until_stopped(None) => r,
    }
}
