//! `serial-bench`: what the serial line framing costs (`flow_lite::line`, docs/protocol.md "Serial lines"), against
//! writing the same frames raw through the same pseudo-terminal pair in the same run.
//!
//! Two linked pseudo-terminals from Debian's `socat`; both ends opened with `tokio-serial`, as the hub and the SDK
//! open a line. 1 KiB publish frames go from one end to the other: raw (the bytes as they are, what TCP would
//! carry), then framed (the SDK's `LineTransport`: COBS around a CRC-32, one packet per frame, decoded and checked
//! by the reader). Rounds alternate; medians are reported. The figures: bytes on the line per message and the
//! overhead of the framing; CPU per message of the whole process (writer and reader), from `/proc/self/stat`;
//! messages per second.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, ensure};
use bytes::{Bytes, BytesMut};
use clap::Parser;
use flow::protocol::{Command as FlowCommand, Envelope, encode_command};
use flow::transport::serial::LineTransport;
use flow::transport::{Transport, TransportRead, TransportWrite};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_serial::SerialPortBuilderExt;

#[derive(Debug, Parser)]
#[command(about = "Serial framing against raw bytes through the same pseudo-terminal")]
struct Args {
    /// Messages per round.
    #[arg(long, default_value_t = 20_000)]
    messages: usize,
    /// Payload bytes per message.
    #[arg(long, default_value_t = 1024)]
    payload: usize,
    /// Rounds of each kind (alternating); medians are reported.
    #[arg(long, default_value_t = 5)]
    rounds: usize,
}

/// CPU time of this process so far (user + system, all threads).
fn cpu() -> anyhow::Result<Duration> {
    let stat = std::fs::read_to_string("/proc/self/stat")?;
    // Fields after the command name (which may hold spaces) start after the last ')'.
    let rest = stat
        .rsplit_once(')')
        .map(|(_, r)| r)
        .context("odd /proc/self/stat")?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: u64 = fields[11].parse::<u64>()? + fields[12].parse::<u64>()?;
    // The kernel's USER_HZ is 100 on every Linux this runs on.
    Ok(Duration::from_millis(ticks * 10))
}

/// One round's figures.
#[derive(Debug, Clone, Copy)]
struct Round {
    wire_bytes: u64,
    cpu: Duration,
    wall: Duration,
}

/// One publish frame of `payload` bytes.
fn frame(payload: usize, n: usize) -> Bytes {
    let body: Vec<u8> = (0..payload).map(|i| (i * 7 + n) as u8).collect();
    let mut out = BytesMut::new();
    encode_command(
        &Envelope {
            req: 0,
            command: FlowCommand::Publish {
                chan: 3,
                payload: Bytes::from(body),
            },
        },
        &mut out,
    );
    out.freeze()
}

async fn raw_round(a: &Path, b: &Path, frames: &[Bytes]) -> anyhow::Result<Round> {
    let mut writer = tokio_serial::new(a.to_string_lossy(), 115_200).open_native_async()?;
    let mut reader = tokio_serial::new(b.to_string_lossy(), 115_200).open_native_async()?;
    let total: u64 = frames.iter().map(|f| f.len() as u64).sum();
    let (cpu0, t0) = (cpu()?, Instant::now());
    let frames = frames.to_vec();
    let write = tokio::spawn(async move {
        for f in &frames {
            writer.write_all(f).await?;
        }
        writer.flush().await?;
        anyhow::Ok(writer)
    });
    let mut got = 0u64;
    let mut buf = vec![0u8; 64 * 1024];
    while got < total {
        let n = reader.read(&mut buf).await?;
        ensure!(n > 0, "the raw line closed");
        got += n as u64;
    }
    let _writer = write.await??;
    Ok(Round {
        wire_bytes: total,
        cpu: cpu()? - cpu0,
        wall: t0.elapsed(),
    })
}

async fn framed_round(a: &Path, b: &Path, frames: &[Bytes]) -> anyhow::Result<Round> {
    let (_, mut writer) = LineTransport::open(a, 115_200)?.split();
    let receiving = LineTransport::open(b, 115_200)?;
    let stats = receiving.stats();
    let (mut reader, _w) = receiving.split();
    let total: u64 = frames.iter().map(|f| f.len() as u64).sum();
    let wire: u64 = frames
        .iter()
        .map(|f| {
            let mut out = vec![0; flow_lite::line::max_encoded_len(f.len())];
            flow_lite::line::encode(f, &mut out).map_or(0, |n| n as u64)
        })
        .sum();
    let (cpu0, t0) = (cpu()?, Instant::now());
    let frames = frames.to_vec();
    let write = tokio::spawn(async move {
        for f in &frames {
            writer.write_all(f).await?;
        }
        anyhow::Ok(writer)
    });
    let mut got = 0u64;
    let mut buf = BytesMut::with_capacity(64 * 1024);
    while got < total {
        buf.clear();
        let n = reader.read_into(&mut buf).await?;
        ensure!(n > 0, "the framed line closed");
        got += n as u64;
    }
    let _writer = write.await??;
    ensure!(stats.damaged() == 0, "{} damaged packets", stats.damaged());
    Ok(Round {
        // The resynchronising zero before the first packet, once per line.
        wire_bytes: wire + 1,
        cpu: cpu()? - cpu0,
        wall: t0.elapsed(),
    })
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let dir = tempfile::Builder::new().prefix("serial-bench-").tempdir()?;
    let (a, b): (PathBuf, PathBuf) = (dir.path().join("a"), dir.path().join("b"));
    let _pty = agent_tests::wires::PtyPair::open(&a, &b).await?;
    let frames: Vec<Bytes> = (0..args.messages).map(|n| frame(args.payload, n)).collect();
    let frame_len = frames[0].len();
    println!(
        "serial-bench: {} messages of {} payload bytes ({frame_len}-byte frames) per round, {} rounds each",
        args.messages, args.payload, args.rounds
    );
    let (mut raw, mut framed) = (Vec::new(), Vec::new());
    for round in 0..args.rounds {
        let r = raw_round(&a, &b, &frames).await?;
        let f = framed_round(&a, &b, &frames).await?;
        println!(
            "round {round}: raw {:.2} s cpu {:.2} s; framed {:.2} s cpu {:.2} s",
            r.wall.as_secs_f64(),
            r.cpu.as_secs_f64(),
            f.wall.as_secs_f64(),
            f.cpu.as_secs_f64()
        );
        raw.push(r);
        framed.push(f);
    }
    let n = args.messages as f64;
    let per_msg =
        |rounds: &[Round], f: fn(&Round) -> f64| median(rounds.iter().map(f).collect()) / n;
    let (raw_bytes, framed_bytes) = (
        per_msg(&raw, |r| r.wire_bytes as f64),
        per_msg(&framed, |r| r.wire_bytes as f64),
    );
    let (raw_cpu, framed_cpu) = (
        per_msg(&raw, |r| r.cpu.as_secs_f64() * 1e6),
        per_msg(&framed, |r| r.cpu.as_secs_f64() * 1e6),
    );
    let (raw_rate, framed_rate) = (
        n / median(raw.iter().map(|r| r.wall.as_secs_f64()).collect()),
        n / median(framed.iter().map(|r| r.wall.as_secs_f64()).collect()),
    );
    let overhead = 100.0 * (framed_bytes / raw_bytes - 1.0);
    println!(
        "SUMMARY serial_framing: {framed_bytes:.1} bytes on the line per {frame_len}-byte frame vs {raw_bytes:.1} raw, \
         overhead {overhead:.2}% (target <= 3%): {}",
        if overhead <= 3.0 { "met" } else { "missed" }
    );
    println!(
        "SUMMARY serial_cpu: {framed_cpu:.2} us of CPU per message framed (COBS + CRC-32 both ways) vs {raw_cpu:.2} us raw \
         through the same pty (ratio {:.2}); {framed_rate:.0} vs {raw_rate:.0} messages/s",
        framed_cpu / raw_cpu
    );
    Ok(())
}
