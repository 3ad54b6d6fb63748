//! Serial lines through a real `flow-hub`: the hub serves a pseudo-terminal (`[[hub.serial]]`), a satellite on the
//! other end of it (Debian's `socat` links two pseudo-terminals) publishes, and a TCP subscriber gets every message
//! intact, from the SDK and from the `flow-lite` sensor sketch a board would run; a relay that flips and drops bytes costs only damaged packets, which the hub counts, and the session
//! survives; a line that goes away and comes back is opened again and the satellite logs in again.

use std::io::{Read, Write};
use std::path::Path;
use std::process::Stdio;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use agent_tests::metrics::{parse, scrape, value};
use agent_tests::wires::{PtyPair, check, payload};
use agent_tests::{Agent, DataDir, PATIENCE, binary, recv_until};
use anyhow::{Context, bail, ensure};
use flow::{Client, ConnectOptions, FlowAddr, Subscription};

/// A hub serving the line at `path`.
async fn hub_on_line(dir: &DataDir, path: &Path) -> anyhow::Result<Agent> {
    Agent::hub_with_config(
        dir,
        &format!(
            "[[hub.serial]]\npath = \"{}\"\nbaud = 115200\n",
            path.display()
        ),
    )
    .await
}

/// A satellite on the line at `path`.
async fn satellite_on(hub: &Agent, path: &Path, reconnect: bool) -> anyhow::Result<Client> {
    let addr: FlowAddr = format!("serial:{}?baud=115200", path.display())
        .parse()
        .map_err(|e: String| anyhow::anyhow!(e))?;
    let mut opts = ConnectOptions::new("board", hub.token());
    opts.reconnect = reconnect;
    Ok(Client::connect(&addr, opts).await?)
}

/// Waits for the first message on `sub`.
async fn first(sub: &Subscription) -> anyhow::Result<Vec<u8>> {
    let data = tokio::time::timeout(PATIENCE, sub.recv())
        .await
        .context("no message")?
        .context("subscription ended")?;
    Ok(data.payload.to_vec())
}

/// The hub's damaged-packet count for the line at `path`.
async fn damaged(hub: &Agent, path: &Path) -> anyhow::Result<f64> {
    let samples = parse(&scrape(hub).await?).await?;
    value(
        &samples,
        "flow_serial_damaged_packets_total",
        &[("line", &path.display().to_string())],
    )
    .context("no flow_serial_damaged_packets_total for the line")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_satellite_on_a_serial_line_publishes_to_a_tcp_subscriber_intact() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let pty = PtyPair::open(&dir.path().join("hub-line"), &dir.path().join("board-line")).await?;
    let hub = hub_on_line(&dir, &pty.a).await?;
    let board = satellite_on(&hub, &pty.b, false).await?;
    let publisher = board
        .publisher("Board.samples", r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let watcher = hub.client("watcher").await?;
    let sub = watcher.subscribe("Board.samples").await?;
    // Small readings and frames longer than one packet's worth of COBS blocks.
    let sizes = [8usize, 100, 1000, 5000, 20_000];
    for seq in 0..50u32 {
        publisher
            .publish(payload(seq, sizes[seq as usize % sizes.len()]))
            .await?;
    }
    for expected in 0..50u32 {
        let p = first(&sub).await?;
        assert_eq!(check(&p)?, expected);
        assert_eq!(p.len(), 8 + sizes[expected as usize % sizes.len()]);
    }
    assert_eq!(damaged(&hub, &pty.a).await?, 0.0);
    Ok(())
}

/// Copies bytes from `from` to `to`, flipping one byte in `flip_every` and dropping one in `drop_every` while
/// `lossy` is set; counts what it spoilt.
fn relay(
    from: std::fs::File,
    to: std::fs::File,
    lossy: Arc<AtomicBool>,
    spoilt: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
) {
    relay_at(from, to, lossy, spoilt, stop, None);
}

/// `relay`, at most `bytes_per_s` when given (a slow line: 11 520 bytes/s is 115 200 baud).
fn relay_at(
    mut from: std::fs::File,
    mut to: std::fs::File,
    lossy: Arc<AtomicBool>,
    spoilt: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
    bytes_per_s: Option<u64>,
) {
    let (flip_every, drop_every) = (10_000u64, 25_000u64);
    let mut n = 0u64;
    let mut buf = [0u8; 4096];
    let started = std::time::Instant::now();
    let mut sent = 0u64;
    while !stop.load(Ordering::Relaxed) {
        let room = if bytes_per_s.is_some() {
            256
        } else {
            buf.len()
        };
        let Ok(got) = from.read(&mut buf[..room]) else {
            return;
        };
        if got == 0 {
            return;
        }
        let mut out = Vec::with_capacity(got);
        for &b in &buf[..got] {
            n += 1;
            if lossy.load(Ordering::Relaxed) {
                if n.is_multiple_of(drop_every) {
                    spoilt.fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                if n.is_multiple_of(flip_every) {
                    spoilt.fetch_add(1, Ordering::Relaxed);
                    out.push(b ^ 0x20);
                    continue;
                }
            }
            out.push(b);
        }
        if let Some(rate) = bytes_per_s {
            sent += out.len() as u64;
            let due = Duration::from_micros(sent * 1_000_000 / rate);
            if let Some(wait) = due.checked_sub(started.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        if to.write_all(&out).is_err() {
            return;
        }
    }
}

fn open_rw(path: &Path) -> anyhow::Result<std::fs::File> {
    std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_line_that_flips_and_drops_bytes_loses_only_damaged_packets_and_the_session_survives()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    // hub <-> [hub-line | relay-a] <-> relay <-> [relay-b | board-line] <-> board
    let hub_side = PtyPair::open(&dir.path().join("hub-line"), &dir.path().join("relay-a")).await?;
    let board_side =
        PtyPair::open(&dir.path().join("relay-b"), &dir.path().join("board-line")).await?;
    let (lossy, spoilt, stop) = (
        Arc::new(AtomicBool::new(false)),
        Arc::new(AtomicU64::new(0)),
        Arc::new(AtomicBool::new(false)),
    );
    let (a, b) = (open_rw(&hub_side.b)?, open_rw(&board_side.a)?);
    for (from, to) in [(b.try_clone()?, a.try_clone()?), (a, b)] {
        let (lossy, spoilt, stop) = (lossy.clone(), spoilt.clone(), stop.clone());
        std::thread::spawn(move || relay(from, to, lossy, spoilt, stop));
    }
    let hub = hub_on_line(&dir, &hub_side.a).await?;
    let board = satellite_on(&hub, &board_side.b, false).await?;
    let publisher = board
        .publisher("Board.samples", r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let watcher = hub.client("watcher").await?;
    let sub = watcher.subscribe("Board.samples").await?;
    // The line goes bad once the session is up: about one packet in ten is spoilt.
    lossy.store(true, Ordering::Relaxed);
    const SENT: u32 = 400;
    for seq in 0..SENT {
        publisher.publish(payload(seq, 1024)).await?;
    }
    // The line heals; a last message proves the session outlived the damage.
    tokio::time::sleep(Duration::from_millis(500)).await;
    lossy.store(false, Ordering::Relaxed);
    publisher.publish(payload(SENT, 16)).await?;
    let mut seen = Vec::new();
    recv_until(&sub, "the last message", PATIENCE * 2, |data| {
        // Never a damaged payload: a packet either arrives whole or not at all.
        match check(&data.payload) {
            Err(e) => Some(Err(e)),
            Ok(seq) if seq == SENT => Some(Ok(())),
            Ok(seq) => {
                seen.push(seq);
                None
            }
        }
    })
    .await??;
    let spoilt = spoilt.load(Ordering::Relaxed);
    let dropped = damaged(&hub, &hub_side.a).await?;
    println!(
        "spoilt {spoilt} bytes; {} of {SENT} delivered; {dropped} packets counted damaged",
        seen.len()
    );
    ensure!(spoilt > 0, "the relay spoilt nothing");
    ensure!(dropped >= 1.0, "no damaged packet counted");
    ensure!(
        seen.windows(2).all(|w| w[0] < w[1]),
        "out of order or repeated: {seen:?}"
    );
    // Each spoilt byte costs at most the two packets it touches (a lost delimiter joins two).
    ensure!(
        seen.len() as u64 + 2 * spoilt >= u64::from(SENT),
        "{} delivered of {SENT} with {spoilt} bytes spoilt",
        seen.len()
    );
    stop.store(true, Ordering::Relaxed);
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_line_that_goes_away_and_comes_back_is_opened_again_and_the_satellite_logs_in_again()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let (a, b) = (dir.path().join("hub-line"), dir.path().join("board-line"));
    let mut pty = PtyPair::open(&a, &b).await?;
    let hub = hub_on_line(&dir, &a).await?;
    let board = satellite_on(&hub, &b, true).await?;
    let publisher = board
        .publisher("Board.samples", r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let watcher = hub.client("watcher").await?;
    let sub = watcher.subscribe("Board.samples").await?;
    publisher.publish(payload(1, 64)).await?;
    assert_eq!(check(&first(&sub).await?)?, 1);
    // Unplugged: both ends go away.
    pty.close();
    hub.output
        .wait_for("cannot open serial line", 1, PATIENCE)
        .await
        .context("the hub did not notice the line went away")?;
    // Plugged in again: the hub opens the line, the satellite logs in again and restores its channel, and the
    // subscriber (whose subscription outlives the channel) hears it again.
    let _pty = PtyPair::open(&a, &b).await?;
    hub.output
        .wait_for("serial line is back", 1, PATIENCE)
        .await
        .context("the hub did not open the line again")?;
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let mut seq = 2;
    loop {
        // Publishing while the satellite reconnects may fail or be lost: keep at it until one arrives.
        let _ = publisher.publish(payload(seq, 64)).await;
        match tokio::time::timeout(Duration::from_millis(500), sub.recv()).await {
            Ok(Some(data)) => {
                check(&data.payload)?;
                break;
            }
            Ok(None) => bail!("subscription ended"),
            Err(_) if tokio::time::Instant::now() < deadline => seq += 1,
            Err(_) => bail!("nothing arrived after the line came back"),
        }
    }
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_flow_lite_sensor_sketch_publishes_through_a_serial_line_to_a_tcp_subscriber()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let pty = PtyPair::open(&dir.path().join("hub-line"), &dir.path().join("board-line")).await?;
    let hub = hub_on_line(&dir, &pty.a).await?;
    let watcher = hub.client("watcher").await?;
    // Subscribed before the board comes up: the channel does not exist yet, and the subscription waits for it. The
    // SDK subscribes when the hub announces the channel, while the sketch, which does not wait for a subscriber
    // (`StartPublishing`), publishes its first reading as soon as the channel is made: a reading that reaches the
    // hub before the subscription does has nobody to go to (on a loaded machine, reading 0 now and then). What is
    // promised is every reading from the subscription on.
    let sub = watcher.subscribe("Sensor.temperature").await?;
    // The sketch as a board runs it: flow-lite alone, fixed buffers, the line's packets.
    let sensor = tokio::process::Command::new(binary("examples/sensor")?)
        .arg(&pty.b)
        .arg(hub.token())
        .args(["--count", "20"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .context("starting the flow-lite sensor example")?;
    let mut expected = None;
    while expected != Some(20) {
        let data = tokio::time::timeout(PATIENCE, sub.recv())
            .await
            .context("no reading")?
            .context("subscription ended")?;
        let reading: serde_json::Value = serde_json::from_slice(&data.payload)?;
        let n = reading["n"]
            .as_u64()
            .with_context(|| format!("{reading}"))?;
        // From the first reading on, each one in turn; the hub numbered every reading it published, also those
        // before the subscription, so the first one's sequence number shows that none was lost on the line.
        ensure!(n < 20, "a reading the sensor never sent: {reading}");
        if expected.is_none() {
            println!("the subscription began with reading {n}");
        }
        assert_eq!(n, expected.unwrap_or(n), "{reading}");
        assert_eq!(data.seq, n + 1, "{reading}");
        assert!(reading["celsius"].as_f64().is_some(), "{reading}");
        expected = Some(n + 1);
    }
    let out = tokio::time::timeout(PATIENCE, sensor.wait_with_output())
        .await
        .context("the sensor did not finish")??;
    ensure!(
        out.status.success(),
        "sensor: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(damaged(&hub, &pty.a).await?, 0.0);
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_subscriber_on_a_slow_line_loses_the_oldest_and_says_so_while_tcp_gets_everything()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let hub_side = PtyPair::open(&dir.path().join("hub-line"), &dir.path().join("relay-a")).await?;
    let board_side =
        PtyPair::open(&dir.path().join("relay-b"), &dir.path().join("board-line")).await?;
    let (lossless, spoilt, stop) = (
        Arc::new(AtomicBool::new(false)),
        Arc::new(AtomicU64::new(0)),
        Arc::new(AtomicBool::new(false)),
    );
    let (a, b) = (open_rw(&hub_side.b)?, open_rw(&board_side.a)?);
    // Towards the board at 115 200 baud; back at full speed.
    for (from, to, rate) in [(a.try_clone()?, b.try_clone()?, Some(11_520)), (b, a, None)] {
        let (lossless, spoilt, stop) = (lossless.clone(), spoilt.clone(), stop.clone());
        std::thread::spawn(move || relay_at(from, to, lossless, spoilt, stop, rate));
    }
    let hub = hub_on_line(&dir, &hub_side.a).await?;
    let board = satellite_on(&hub, &board_side.b, false).await?;
    let slow = board.subscribe("Fast.samples").await?;
    let source = hub.client("source").await?;
    let watcher = hub.client("watcher").await?;
    let fast = watcher.subscribe("Fast.samples").await?;
    let publisher = source
        .publisher("Fast.samples", r#"{"mime":"application/octet-stream"}"#)
        .await?;
    // Both subscribers are there before the first message.
    let deadline = tokio::time::Instant::now() + PATIENCE;
    while source
        .channels()
        .await?
        .iter()
        .find(|c| c.name == "Fast.samples")
        .is_none_or(|c| c.stats.subscribers < 2)
    {
        ensure!(
            tokio::time::Instant::now() < deadline,
            "the board never subscribed"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // 100 messages of 2 kB a second: 200 kB/s, which TCP carries easily (a TCP subscriber would have to fall 640 ms
    // behind to lose one) and the line at 11.5 kB/s cannot; the board's lane (64 messages) fills and the hub drops
    // its oldest.
    const SENT: u32 = 200;
    for seq in 0..SENT {
        publisher.publish(payload(seq, 2000)).await?;
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    // The TCP subscriber is not held back by the line: it has everything, in order, while the line still drains.
    for expected in 0..SENT {
        assert_eq!(check(&first(&fast).await?)?, expected);
    }
    // The board gets the newest, intact, and the hub's sequence numbers show what it lost.
    let (mut got, mut last_seq, mut gaps) = (0u32, 0u64, 0u64);
    recv_until(
        &slow,
        "the newest message over the slow line",
        PATIENCE * 2,
        |data| {
            let seq = match check(&data.payload) {
                Ok(seq) => seq,
                Err(e) => return Some(Err(e)),
            };
            got += 1;
            gaps += data.seq - last_seq - 1;
            last_seq = data.seq;
            (seq == SENT - 1).then_some(Ok(()))
        },
    )
    .await
    .context("the slow line delivered nothing more")??;
    let dropped = source
        .channels()
        .await?
        .iter()
        .find(|c| c.name == "Fast.samples")
        .map_or(0, |c| c.stats.dropped);
    println!("the slow line got {got} of {SENT}; gaps {gaps}; the hub dropped {dropped}");
    ensure!(
        got < SENT,
        "a 115 200-baud line kept up with {SENT} messages of 2 kB"
    );
    assert_eq!(u64::from(got) + gaps, u64::from(SENT));
    ensure!(
        dropped >= gaps,
        "the hub counted {dropped} drops for {gaps} missing"
    );
    stop.store(true, Ordering::Relaxed);
    Ok(())
}
