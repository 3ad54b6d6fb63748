//! Zero-copy shared memory between the hub and satellites on the same machine (issue 39), through a real `flow-hub`
//! and real satellite processes: what a Unix-socket subscriber reads by reference is what a TCP subscriber reads by
//! copy; `kill -9` of a publisher or a subscriber process leaks no segment, slot, mapping or descriptor in the hub;
//! a stopped subscriber loses its oldest messages, counted, while the publisher never waits (inline, counted as
//! spilled, once the stopped one holds every slot); a connection that has not logged in gets no segment.
//!
//! Build the binaries first: `cargo build -p flow-hub -p flowctl`.

use std::collections::VecDeque;
use std::os::fd::OwnedFd;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use agent_tests::metrics::scrape;
use agent_tests::{Agent, DataDir, PATIENCE, http, recv, recv_until, until, until_subscribed};
use anyhow::{Context, anyhow, bail};
use bytes::{BufMut, Bytes, BytesMut};
use flow::protocol::frame::{self, Check};
use flow::protocol::{
    ChanRef, ChannelKind, Command, DEFAULT_MAX_FRAME, Envelope, ErrorCode, ErrorReply, Event,
    PROTOCOL_VERSION, Reply, SlotRef, decode_event, encode_command,
};
use flow::shm::fdpass::recv_with_fds;
use flow::shm::ring::{self, Pushed, RingWriter};
use flow::shm::{Mapping, is_shared};
use flow::{Client, Publisher, Subscription};
use rand::seq::SliceRandom;
use rand::{RngCore, SeedableRng};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt};
use tokio::process::Child;
use tokio::sync::watch;
use tokio::task::JoinHandle;

/// The hub's default `hub.shm_threshold`: payloads of this size and more travel by reference.
const THRESHOLD: usize = 4096;
/// How long a gauge or a process may take to settle on a machine busy building; nothing here is timed.
const SETTLE: Duration = Duration::from_secs(60);
/// What the hub's memfd segments are called in `/proc/PID/maps` and `/proc/PID/fd`.
const MEMFD: &str = "memfd:flow-shm";
/// What a subscriber's release ring is called there.
const RING_MEMFD: &str = "memfd:flow-release";

// ---------------------------------------------------------------- the hub seen from outside

/// The sum of the samples of `name` on the hub's `/metrics` whose labels contain `labels` (`""`: all of them);
/// an error if there is none, naming the shared-memory lines there are.
async fn metric_with(agent: &Agent, name: &str, labels: &str) -> anyhow::Result<f64> {
    let text = scrape(agent).await?;
    let mut found = None;
    for line in text.lines().filter(|l| !l.starts_with('#')) {
        let Some((sample, value)) = line.rsplit_once(' ') else {
            continue;
        };
        let (base, rest) = sample.split_once('{').unwrap_or((sample, ""));
        if base == name && rest.contains(labels) {
            let v: f64 = value.parse().with_context(|| format!("sample {line:?}"))?;
            *found.get_or_insert(0.0) += v;
        }
    }
    found.with_context(|| {
        let shm: Vec<_> = text.lines().filter(|l| l.contains("flow_shm")).collect();
        format!(
            "/metrics has no {name}{{{labels}}}; its shared-memory lines:\n{}",
            shm.join("\n")
        )
    })
}

async fn metric(agent: &Agent, name: &str) -> anyhow::Result<f64> {
    metric_with(agent, name, "").await
}

/// Polls `name` until `ok` holds; fails after [`SETTLE`] with the last value and `expected`.
async fn until_metric(
    agent: &Agent,
    name: &str,
    expected: &str,
    ok: impl Fn(f64) -> bool,
) -> anyhow::Result<f64> {
    let deadline = tokio::time::Instant::now() + SETTLE;
    loop {
        let v = metric(agent, name).await?;
        if ok(v) {
            return Ok(v);
        }
        if tokio::time::Instant::now() > deadline {
            bail!("{name} stayed at {v}, expected {expected}");
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// The hub's shared-memory segments as the kernel sees them: mappings and open descriptors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Memfds {
    maps: usize,
    fds: usize,
}

impl Memfds {
    fn total(self) -> usize {
        self.maps + self.fds
    }
}

fn hub_memfds(agent: &Agent) -> anyhow::Result<Memfds> {
    let pid = agent.pid().context("the hub has exited")?;
    let maps = std::fs::read_to_string(format!("/proc/{pid}/maps"))
        .with_context(|| format!("reading /proc/{pid}/maps"))?
        .lines()
        .filter(|l| l.contains(MEMFD))
        .count();
    Ok(Memfds {
        maps,
        fds: hub_fds(agent, MEMFD)?,
    })
}

/// The hub's open descriptors whose target names `what`.
fn hub_fds(agent: &Agent, what: &str) -> anyhow::Result<usize> {
    let pid = agent.pid().context("the hub has exited")?;
    let mut fds = 0;
    for entry in std::fs::read_dir(format!("/proc/{pid}/fd"))? {
        // A descriptor closed between the listing and the look is gone: not counted.
        if let Ok(target) = std::fs::read_link(entry?.path())
            && target.to_string_lossy().contains(what)
        {
            fds += 1;
        }
    }
    Ok(fds)
}

/// The hub's release rings (one per shared-memory subscriber) as open descriptors.
fn hub_rings(agent: &Agent) -> anyhow::Result<usize> {
    hub_fds(agent, RING_MEMFD)
}

/// Polls the hub's release rings until there are `expected`.
async fn until_rings(agent: &Agent, expected: usize) -> anyhow::Result<()> {
    let deadline = tokio::time::Instant::now() + SETTLE;
    loop {
        let now = hub_rings(agent)?;
        if now == expected {
            return Ok(());
        }
        if tokio::time::Instant::now() > deadline {
            bail!("the hub holds {now} release rings, expected {expected}");
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Polls the hub's memfd mappings and descriptors until `ok` holds.
async fn until_memfds(
    agent: &Agent,
    expected: &str,
    ok: impl Fn(Memfds) -> bool,
) -> anyhow::Result<Memfds> {
    let deadline = tokio::time::Instant::now() + SETTLE;
    loop {
        let now = hub_memfds(agent)?;
        if ok(now) {
            return Ok(now);
        }
        if tokio::time::Instant::now() > deadline {
            let pid = agent.pid().unwrap_or(0);
            let maps = std::fs::read_to_string(format!("/proc/{pid}/maps")).unwrap_or_default();
            let ours: Vec<_> = maps.lines().filter(|l| l.contains(MEMFD)).collect();
            bail!(
                "the hub's segments stayed at {now:?}, expected {expected}; its {MEMFD} mappings:\n{}",
                ours.join("\n")
            );
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Entries of `/dev/shm` that could be ours: memfd segments must never appear there.
fn dev_shm_flow() -> anyhow::Result<Vec<String>> {
    let Ok(dir) = std::fs::read_dir("/dev/shm") else {
        return Ok(Vec::new());
    };
    let mut names = Vec::new();
    for entry in dir {
        let name = entry?.file_name().to_string_lossy().into_owned();
        if name.contains("flow") {
            names.push(name);
        }
    }
    names.sort();
    Ok(names)
}

/// `until_channel`'s opposite: waits until `name` no longer exists on the hub.
async fn until_gone(client: &Client, name: &str) -> anyhow::Result<()> {
    tokio::time::timeout(SETTLE, async {
        while client.channel(name).await.is_ok() {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    })
    .await
    .with_context(|| format!("{name} outlived its owner"))
}

fn unix_addr(agent: &Agent) -> String {
    format!("unix:{}", agent.flow_unix.display())
}

// ---------------------------------------------------------------- streams inside the test

/// `size` bytes starting with `n` (the seq it gets on a fresh channel), the rest 0xff: never UTF-8, so `flowctl
/// echo` prints it as a `<N bytes> seq=S` line.
fn numbered(n: u64, size: usize) -> Bytes {
    let mut payload = BytesMut::with_capacity(size);
    payload.put_u64_le(n);
    payload.resize(size, 0xff);
    payload.freeze()
}

/// A task publishing numbered `size`-byte messages, one every `period`, until stopped; `sent` counts them.
#[derive(Debug)]
struct Streamer {
    stop: Arc<AtomicBool>,
    sent: watch::Receiver<u64>,
    task: JoinHandle<anyhow::Result<Publisher>>,
}

fn stream(publisher: Publisher, size: usize, period: Duration) -> Streamer {
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, sent) = watch::channel(0u64);
    let flag = stop.clone();
    let task = tokio::spawn(async move {
        let mut tick = tokio::time::interval(period);
        let mut n = 0u64;
        while !flag.load(Ordering::Relaxed) {
            tick.tick().await;
            n += 1;
            publisher.publish(numbered(n, size)).await?;
            tx.send_replace(n);
        }
        Ok(publisher)
    });
    Streamer { stop, sent, task }
}

impl Streamer {
    /// Stops publishing; the publisher (and so its channel) is handed back with the count sent.
    async fn finish(self) -> anyhow::Result<(Publisher, u64)> {
        self.stop.store(true, Ordering::Relaxed);
        let publisher = tokio::time::timeout(PATIENCE, self.task)
            .await
            .context("the publisher did not stop")???;
        let sent = *self.sent.borrow();
        Ok((publisher, sent))
    }
}

/// A task reading `sub` as fast as it can, checking (if `numbered`) that each payload carries its seq, and dropping
/// it at once (so it holds no slot); `seen` is the last seq.
fn consume(
    sub: Subscription,
    numbered: bool,
) -> (watch::Receiver<u64>, JoinHandle<anyhow::Result<()>>) {
    let (tx, seen) = watch::channel(0u64);
    let task = tokio::spawn(async move {
        while let Some(got) = sub.recv().await {
            if numbered && got.payload.get(..8) != Some(&got.seq.to_le_bytes()[..]) {
                bail!("{}: message {} carries another number", sub.name(), got.seq);
            }
            tx.send_replace(got.seq);
        }
        Ok(())
    });
    (seen, task)
}

/// Waits until a counter reaches `at_least`.
async fn until_count(
    count: &mut watch::Receiver<u64>,
    at_least: u64,
    what: &str,
) -> anyhow::Result<()> {
    let reached = tokio::time::timeout(SETTLE, count.wait_for(|n| *n >= at_least))
        .await
        .map(|r| r.is_ok());
    match reached {
        Ok(true) => Ok(()),
        Ok(false) => bail!("{what} ended before {at_least}"),
        Err(_) => bail!("{what} stalled at {} below {at_least}", *count.borrow()),
    }
}

/// Fails with a consumer's error if it has failed; stops it otherwise.
async fn check_consumer(task: JoinHandle<anyhow::Result<()>>) -> anyhow::Result<()> {
    if task.is_finished() {
        return task.await.context("the consumer panicked")?;
    }
    task.abort();
    Ok(())
}

/// Publishes numbered `size`-byte messages until one reaches `sub` by reference, reading `others` alongside;
/// returns how many were published. The SDK sends a channel's first large message inline while it asks the hub for
/// a segment sized for it (a publisher never waits), so a stream goes by reference once the segment has come.
async fn until_by_reference(
    publisher: &Publisher,
    sub: &Subscription,
    others: &[&Subscription],
    size: usize,
) -> anyhow::Result<u64> {
    let what = format!("a message by reference on {}", sub.name());
    until(&what, SETTLE, async {
        for n in 1..=1000 {
            publisher.publish(numbered(n, size)).await?;
            let got = recv(sub).await?;
            for other in others {
                recv(other).await?;
            }
            if is_shared(&got.payload) {
                return Ok(n);
            }
        }
        bail!(
            "1000 messages of {size} B on {} and none came by reference",
            publisher.name()
        )
    })
    .await?
}

// ---------------------------------------------------------------- satellite processes

/// `flowctl echo NAME` over the Unix socket in a process of its own (so shared memory, by default), with the seqs
/// it prints collected in `seqs`.
#[derive(Debug)]
struct Echo {
    child: Child,
    seqs: watch::Receiver<Vec<u64>>,
}

fn echo(agent: &Agent, name: &str) -> anyhow::Result<Echo> {
    let mut cmd = agent.flowctl_at(&unix_addr(agent))?;
    cmd.env_remove("FLOW_SHM")
        .args(["--login", "echo", "echo", name])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::inherit());
    let mut child = cmd.spawn().context("starting flowctl echo")?;
    let stdout = child.stdout.take().context("no stdout")?;
    let (tx, seqs) = watch::channel(Vec::new());
    // Read at all times, so a full pipe never stalls the process behind the test's back.
    tokio::spawn(async move {
        let mut lines = tokio::io::BufReader::new(stdout).lines();
        while let Ok(Some(line)) = lines.next_line().await {
            let seq = line
                .split_whitespace()
                .find_map(|w| w.strip_prefix("seq="))
                .and_then(|s| s.parse::<u64>().ok());
            if let Some(seq) = seq {
                tx.send_modify(|v| v.push(seq));
            }
        }
    });
    Ok(Echo { child, seqs })
}

impl Echo {
    async fn until_printed(&mut self, at_least: usize) -> anyhow::Result<()> {
        tokio::time::timeout(SETTLE, self.seqs.wait_for(|v| v.len() >= at_least))
            .await
            .context("flowctl echo printed too little")?
            .context("flowctl echo's output ended")?;
        Ok(())
    }
}

/// `kill -SIG PID`.
fn signal(child: &Child, sig: &str) -> anyhow::Result<()> {
    let pid = child.id().context("the process has exited")?;
    let status = std::process::Command::new("kill")
        .arg(format!("-{sig}"))
        .arg(pid.to_string())
        .status()
        .context("running kill")?;
    anyhow::ensure!(status.success(), "kill -{sig} {pid} failed");
    Ok(())
}

/// SIGKILL, and waits for the process to be gone.
async fn kill9(child: &mut Child) -> anyhow::Result<()> {
    child.start_kill().context("kill -9")?;
    tokio::time::timeout(PATIENCE, child.wait())
        .await
        .context("the killed process did not go")??;
    Ok(())
}

// ---------------------------------------------------------------- the tests

#[tokio::test]
async fn data_is_identical_between_a_shared_memory_subscriber_and_a_tcp_subscriber()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let dev_shm = dev_shm_flow()?;
    let producer = agent.unix_client("shm-producer").await?;
    let local = agent.unix_client("shm-local").await?;
    let remote = agent.client("tcp-remote").await?;
    let publisher = producer
        .publisher("Shm.frames", r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let by_reference = local.subscribe("Shm.frames").await?;
    let by_copy = remote.subscribe("Shm.frames").await?;
    until_subscribed(&publisher).await?;
    // The channel's segment, sized for its largest message, is in place before the stream under test.
    let warm = until_by_reference(&publisher, &by_reference, &[&by_copy], 1 << 20).await?;

    // 200 sizes from 100 B to 1 MB on a log scale, with both sides of the threshold, in a random order.
    let mut rng = rand::rngs::StdRng::seed_from_u64(39);
    let mut sizes: Vec<usize> = (0..198)
        .map(|i| (100.0 * (1_048_576.0f64 / 100.0).powf(f64::from(i) / 197.0)).round() as usize)
        .collect();
    sizes.extend([THRESHOLD - 1, THRESHOLD]);
    sizes.shuffle(&mut rng);
    let by_reference_before = metric(&agent, "flow_shm_messages_total").await?;
    // Spilling is the publisher's: its SDK counts the messages it sent inline because every slot was held.
    let spilled_before = producer.shm_spilled();
    let mut large = 0.0;
    for (i, &size) in sizes.iter().enumerate() {
        let mut payload = vec![0u8; size];
        rng.fill_bytes(&mut payload);
        payload[..8].copy_from_slice(&(i as u64).to_le_bytes());
        let payload = Bytes::from(payload);
        publisher.publish(payload.clone()).await?;
        // One message at a time: this test is about what arrives; a full segment is another test's.
        let a = recv(&by_reference).await?;
        let b = recv(&by_copy).await?;
        let seq = warm + i as u64 + 1;
        assert_eq!((a.seq, b.seq), (seq, seq), "message {i} ({size} B)");
        assert_eq!(a.ts_us, b.ts_us, "message {i} ({size} B): two timestamps");
        // `assert!` rather than `assert_eq!`: a megabyte in a failure message helps nobody.
        assert!(
            a.payload == payload,
            "message {i} ({size} B) differs over the Unix socket"
        );
        assert!(
            b.payload == payload,
            "message {i} ({size} B) differs over TCP"
        );
        assert_eq!(
            is_shared(&a.payload),
            size >= THRESHOLD,
            "message {i} ({size} B) over the Unix socket: by reference exactly from {THRESHOLD} B on"
        );
        assert!(
            !is_shared(&b.payload),
            "message {i} ({size} B) over TCP lies in shared memory"
        );
        if size >= THRESHOLD {
            large += 1.0;
        }
    }
    assert_eq!(
        metric(&agent, "flow_shm_messages_total").await? - by_reference_before,
        large,
        "messages published by reference"
    );
    // The hub maps what it copies to the TCP subscriber: the marker the leak checks look for is the right one.
    let live = hub_memfds(&agent)?;
    assert!(
        live.total() > 0,
        "no {MEMFD} mapping or descriptor in the hub while segments are in use: {live:?}"
    );
    // Every view has been dropped: every slot comes back.
    until_metric(&agent, "flow_shm_slots_held", "0", |v| v == 0.0).await?;

    // Everyone leaves: nothing remains in the hub, and nothing ever appeared in /dev/shm.
    drop((by_reference, by_copy, publisher));
    for client in [&producer, &local, &remote] {
        client.close_and_wait(PATIENCE).await;
    }
    until_metric(&agent, "flow_shm_segments", "0", |v| v == 0.0).await?;
    until_memfds(&agent, "none", |m| m.total() == 0).await?;
    assert_eq!(dev_shm_flow()?, dev_shm);
    assert_eq!(
        producer.shm_spilled() - spilled_before,
        0,
        "messages spilled with a subscriber that keeps up"
    );
    Ok(())
}

#[tokio::test]
async fn kill_9_of_a_publisher_process_mid_stream_leaks_nothing_and_the_rest_continue()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let dev_shm = dev_shm_flow()?;
    // Another pair streams over the Unix socket the whole time.
    let other_owner = agent.unix_client("other-pub").await?;
    let other_reader = agent.unix_client("other-sub").await?;
    let other_pub = other_owner.publisher("Shm.other", "{}").await?;
    let (mut other_seen, other_task) = consume(other_reader.subscribe("Shm.other").await?, true);
    until_subscribed(&other_pub).await?;
    let other = stream(other_pub, 64 * 1024, Duration::from_millis(5));
    until_count(&mut other_seen, 20, "the other pair").await?;
    // The victim's subscribers are there before its channel: one by reference, one over TCP (which the hub serves
    // from the victim's segment).
    let watcher = agent.unix_client("victim-sub").await?;
    let victim_sub = watcher.subscribe("Shm.victim").await?;
    let remote = agent.client("victim-tcp").await?;
    let (_, remote_task) = consume(remote.subscribe("Shm.victim").await?, false);
    let segments_before = metric(&agent, "flow_shm_segments").await?;
    let memfds_before = hub_memfds(&agent)?;

    // The victim: flowctl publishing four 256 kB frames in a loop over the Unix socket, a process of its own.
    let frames = tempfile::tempdir()?;
    for i in 0..4u8 {
        std::fs::write(frames.path().join(format!("{i}.bin")), vec![i; 256 * 1024])?;
    }
    let mut cmd = agent.flowctl_at(&unix_addr(&agent))?;
    cmd.env_remove("FLOW_SHM")
        .args(["--login", "victim", "pub", "Shm.victim", "--dir"])
        .arg(frames.path())
        .args(["--rate", "100", "--repeat", "1000000"])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::inherit());
    let mut victim = cmd.spawn().context("starting flowctl pub")?;
    // What arrives lies in shared memory (from the message after the channel's segment came: the SDK sends the
    // first one inline while it asks for it); the last three views are kept past the publisher's death.
    let mut inline = 0;
    recv_until(&victim_sub, "a frame by reference", PATIENCE, |got| {
        if is_shared(&got.payload) {
            return Some(Ok(()));
        }
        inline += 1;
        (inline >= 100).then(|| {
            Err(anyhow!(
                "100 of flowctl's frames and none came by reference"
            ))
        })
    })
    .await??;
    let mut held = Vec::new();
    for _ in 0..20 {
        let got = recv(&victim_sub).await?;
        assert_eq!(got.payload.len(), 256 * 1024);
        assert!(
            is_shared(&got.payload),
            "flowctl's frame {} did not come by reference",
            got.seq
        );
        held.push(got);
        if held.len() > 3 {
            held.remove(0);
        }
    }
    until_metric(
        &agent,
        "flow_shm_segments",
        &format!("more than the {segments_before} before the victim"),
        |v| v > segments_before,
    )
    .await?;
    until_memfds(&agent, "more than before the victim", |m| {
        m.total() > memfds_before.total()
    })
    .await?;

    println!(
        "before the victim: {segments_before} segment(s), {memfds_before:?}; streaming: {} segment(s), {:?}, \
         {inline} frame(s) inline first",
        metric(&agent, "flow_shm_segments").await?,
        hub_memfds(&agent)?
    );
    kill9(&mut victim).await?;
    until_gone(&watcher, "Shm.victim").await?;
    // The other pair goes on.
    let reached = *other_seen.borrow();
    until_count(
        &mut other_seen,
        reached + 50,
        "the other pair after the kill",
    )
    .await?;
    // Views held past the publisher's death still read its bytes (file i is all i).
    for got in &held {
        let first = got.payload[0];
        assert!(
            first < 4 && got.payload.iter().all(|b| *b == first),
            "message {} changed after its publisher died",
            got.seq
        );
    }
    // Once they are dropped, the hub holds what it held before the victim came: segments, mappings, descriptors.
    drop(held);
    while victim_sub.try_recv().is_some() {}
    until_metric(
        &agent,
        "flow_shm_segments",
        &format!("{segments_before}"),
        |v| v == segments_before,
    )
    .await?;
    until_memfds(&agent, &format!("{memfds_before:?}"), |m| {
        m == memfds_before
    })
    .await?;

    // The other pair stops; its last message arrives, and no slot is held by anyone.
    let (other_pub, sent) = other.finish().await?;
    until_count(&mut other_seen, sent, "the other pair's last message").await?;
    until_metric(&agent, "flow_shm_slots_held", "0", |v| v == 0.0).await?;
    check_consumer(other_task).await?;
    check_consumer(remote_task).await?;
    // Everyone leaves: nothing remains.
    drop((other_pub, victim_sub));
    for client in [&other_owner, &other_reader, &watcher, &remote] {
        client.close_and_wait(PATIENCE).await;
    }
    until_metric(&agent, "flow_shm_segments", "0", |v| v == 0.0).await?;
    until_memfds(&agent, "none", |m| m.total() == 0).await?;
    assert_eq!(dev_shm_flow()?, dev_shm);
    Ok(())
}

#[tokio::test]
async fn kill_9_of_a_subscriber_process_mid_stream_releases_its_slots_and_the_rest_continue()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub_with_config(&dir, "[hub]\nsubscriber_queue = 16\n").await?;
    let producer = agent.unix_client("producer").await?;
    let reader = agent.unix_client("live-sub").await?;
    let publisher = producer.publisher("Shm.watched", "{}").await?;
    let (mut live_seen, live_task) = consume(reader.subscribe("Shm.watched").await?, true);
    until_subscribed(&publisher).await?;
    let mut streamer = stream(publisher, 128 * 1024, Duration::from_millis(5));
    until_count(&mut live_seen, 20, "the live subscriber").await?;
    let segments_before = metric(&agent, "flow_shm_segments").await?;
    let memfds_before = hub_memfds(&agent)?;
    let rings_before = hub_rings(&agent)?;

    // The victim: flowctl echo over the Unix socket. Stopped, it reads nothing, so what the hub queues for it keeps
    // its slots; then it is killed.
    let mut victim = echo(&agent, "Shm.watched")?;
    victim.until_printed(10).await?;
    signal(&victim.child, "STOP")?;
    let pinned = until_metric(
        &agent,
        "flow_shm_slots_held",
        "4 or more while a subscriber is stopped",
        |v| v >= 4.0,
    )
    .await?;
    println!("slots held with the subscriber stopped: {pinned}");
    kill9(&mut victim.child).await?;

    // The publisher and the live subscriber go on.
    let sent = *streamer.sent.borrow();
    until_count(
        &mut streamer.sent,
        sent + 50,
        "the publisher after the kill",
    )
    .await?;
    until_count(
        &mut live_seen,
        sent + 50,
        "the live subscriber after the kill",
    )
    .await?;
    // Stopped at last, with the live subscriber done: no slot is held, the victim's included.
    let (publisher, sent) = streamer.finish().await?;
    until_count(&mut live_seen, sent, "the live subscriber's last message").await?;
    until_metric(
        &agent,
        "flow_shm_slots_held",
        &format!("0 (was {pinned} with the stopped subscriber)"),
        |v| v == 0.0,
    )
    .await?;
    until_metric(
        &agent,
        "flow_shm_segments",
        &format!("{segments_before}, as before the victim came"),
        |v| v == segments_before,
    )
    .await?;
    until_memfds(&agent, &format!("{memfds_before:?}"), |m| {
        m == memfds_before
    })
    .await?;
    // Its release ring went with it.
    until_rings(&agent, rings_before).await?;
    check_consumer(live_task).await?;
    drop(publisher);
    Ok(())
}

#[tokio::test]
async fn a_stalled_shared_memory_subscriber_loses_its_oldest_messages_counted_while_the_publisher_never_waits()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub_with_config(&dir, "[hub]\nsubscriber_queue = 16\n").await?;
    let producer = agent.unix_client("producer").await?;
    let reader = agent.unix_client("live-sub").await?;
    let publisher = producer.publisher("Shm.stalled", "{}").await?;
    let live = reader.subscribe("Shm.stalled").await?;
    let mut stalled = echo(&agent, "Shm.stalled")?;
    tokio::time::timeout(SETTLE, async {
        while producer.channel("Shm.stalled").await?.stats.subscribers < 2 {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        anyhow::Ok(())
    })
    .await
    .context("flowctl echo did not subscribe")??;
    until_subscribed(&publisher).await?;

    const SIZE: usize = 128 * 1024;
    let mut n = 0u64;
    // Each publish is followed by its delivery to the live subscriber: a publisher held back by the stopped one
    // would stop this loop (a timeout), not merely slow it.
    let publish_one = async |n: u64| -> anyhow::Result<()> {
        publisher.publish(numbered(n, SIZE)).await?;
        let got = recv(&live).await?;
        anyhow::ensure!(
            got.seq == n && got.payload.get(..8) == Some(&n.to_le_bytes()[..]),
            "the live subscriber got message {} for {n}",
            got.seq
        );
        Ok(())
    };
    n += 1;
    publish_one(n).await?;
    stalled.until_printed(1).await?;
    signal(&stalled.child, "STOP")?;
    let stopped_at = n;
    // Until the hub counts drops on the channel (and at least 300 messages past the stop).
    until("a drop counted on Shm.stalled", SETTLE * 2, async {
        loop {
            n += 1;
            publish_one(n).await?;
            if n.is_multiple_of(50) && n >= stopped_at + 300 {
                let info = producer.channel("Shm.stalled").await?;
                if info.stats.dropped > 0 {
                    return Ok(());
                }
            }
            if n > stopped_at + 20_000 {
                bail!("no drop counted after 20000 messages past a stopped subscriber");
            }
        }
    })
    .await
    .with_context(|| format!("{} messages past the stop", n - stopped_at))??;
    assert_eq!(live.dropped(), 0, "the live subscriber lost messages");
    // Counted where operators look: /api/channels and /metrics.
    let list = http::get_json(agent.http, "/api/channels", agent.token()).await?;
    let channel = list
        .as_array()
        .and_then(|l| l.iter().find(|c| c["name"] == "Shm.stalled"))
        .context("Shm.stalled missing from /api/channels")?;
    assert!(
        channel["dropped"].as_u64().is_some_and(|d| d > 0),
        "{channel}"
    );
    assert!(
        metric_with(
            &agent,
            "flow_channel_dropped_total",
            "channel=\"Shm.stalled\""
        )
        .await?
            > 0.0,
        "flow_channel_dropped_total of Shm.stalled is 0"
    );
    println!(
        "stalled subscriber: {} messages published, {} dropped on the channel; shm messages {}, spilled {}",
        n,
        channel["dropped"],
        metric(&agent, "flow_shm_messages_total").await?,
        producer.shm_spilled()
    );

    // Woken, the stalled subscriber finds a gap where its oldest messages were, then the newest one.
    signal(&stalled.child, "CONT")?;
    tokio::time::timeout(SETTLE, stalled.seqs.wait_for(|v| v.last() == Some(&n)))
        .await
        .context("the woken subscriber never got the newest message")?
        .context("flowctl echo's output ended")?;
    let seqs = stalled.seqs.borrow().clone();
    assert!(
        seqs.windows(2).all(|w| w[0] < w[1]),
        "out of order: {seqs:?}"
    );
    assert!(
        seqs.windows(2).any(|w| w[1] > w[0] + 1),
        "no gap: the stopped subscriber received everything"
    );
    kill9(&mut stalled.child).await?;
    until_metric(&agent, "flow_shm_slots_held", "0", |v| v == 0.0).await?;
    Ok(())
}

#[tokio::test]
async fn a_publisher_whose_slots_are_all_held_sends_inline_counted_and_never_waits()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    // Four slots a segment, and a subscriber may hold eight: one stopped subscriber can hold them all.
    let agent = Agent::hub_with_config(
        &dir,
        "[hub]\nsubscriber_queue = 16\nshm_slots = 4\nshm_held = 8\n",
    )
    .await?;
    let producer = agent.unix_client("producer").await?;
    let reader = agent.unix_client("live-sub").await?;
    let publisher = producer.publisher("Shm.full", "{}").await?;
    let live = reader.subscribe("Shm.full").await?;
    let mut stalled = echo(&agent, "Shm.full")?;
    tokio::time::timeout(SETTLE, async {
        while producer.channel("Shm.full").await?.stats.subscribers < 2 {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        anyhow::Ok(())
    })
    .await
    .context("flowctl echo did not subscribe")??;
    const SIZE: usize = 64 * 1024;
    let mut n = until_by_reference(&publisher, &live, &[], SIZE).await?;
    stalled.until_printed(1).await?;
    signal(&stalled.child, "STOP")?;
    let spilled_before = producer.shm_spilled();

    // In step with the live subscriber, as in the test above: the publisher must go on, inline once every slot is
    // held by the stopped subscriber.
    let mut inline = 0u64;
    for _ in 0..200 {
        n += 1;
        publisher.publish(numbered(n, SIZE)).await?;
        let got = recv(&live).await?;
        assert!(
            got.seq == n && got.payload.get(..8) == Some(&n.to_le_bytes()[..]),
            "the live subscriber got message {} for {n}",
            got.seq
        );
        inline += u64::from(!is_shared(&got.payload));
    }
    let spilled = producer.shm_spilled();
    println!(
        "200 messages with every slot held: {inline} reached the live subscriber inline; \
         the publisher's Client::shm_spilled {spilled_before} -> {spilled}"
    );
    assert!(inline > 0, "no message went inline with every slot held");
    signal(&stalled.child, "CONT")?;
    kill9(&mut stalled.child).await?;
    until_metric(&agent, "flow_shm_slots_held", "0", |v| v == 0.0).await?;
    assert!(
        spilled > spilled_before,
        "the publisher counted no spilled message"
    );
    Ok(())
}

/// A FlowProtocol connection over the Unix socket driven by hand, keeping every descriptor the hub passes beside
/// its bytes: for what the SDK never sends (shared-memory commands before login).
#[derive(Debug)]
struct RawUnix {
    stream: tokio::net::UnixStream,
    buf: BytesMut,
    /// Where `recvmsg` writes before the bytes join `buf`.
    scratch: Vec<u8>,
    fds: VecDeque<OwnedFd>,
    next_req: u32,
}

impl RawUnix {
    async fn connect(agent: &Agent) -> anyhow::Result<RawUnix> {
        let stream = tokio::net::UnixStream::connect(&agent.flow_unix)
            .await
            .context("connecting to the Unix socket")?;
        Ok(RawUnix {
            stream,
            buf: BytesMut::new(),
            scratch: vec![0; 64 * 1024],
            fds: VecDeque::new(),
            next_req: 1,
        })
    }

    async fn login(agent: &Agent) -> anyhow::Result<RawUnix> {
        let mut conn = Self::connect(agent).await?;
        let reply = conn
            .request(Command::Login {
                version: PROTOCOL_VERSION,
                token: agent.token().into(),
                name: "raw-unix".into(),
            })
            .await?;
        anyhow::ensure!(
            matches!(reply, Ok(Reply::LoginOk { .. })),
            "login: {reply:?}"
        );
        // Shared memory is for asynchronous connections (data events reach no other kind).
        let reply = conn.request(Command::SetAsync).await?;
        anyhow::ensure!(reply.is_ok(), "set async: {reply:?}");
        Ok(conn)
    }

    async fn send(&mut self, command: Command) -> anyhow::Result<u32> {
        let req = self.next_req;
        self.next_req += 1;
        let mut frame = BytesMut::new();
        encode_command(&Envelope { req, command }, &mut frame);
        self.stream.write_all(&frame).await.context("sending")?;
        Ok(req)
    }

    /// The next event, or `None` once the hub has closed the connection.
    async fn next_event(&mut self) -> anyhow::Result<Option<Event>> {
        loop {
            if let Check::Complete(total) = frame::check(&self.buf, DEFAULT_MAX_FRAME)? {
                let raw = frame::parse(&mut self.buf, total);
                return Ok(Some(decode_event(raw)?));
            }
            let read = tokio::time::timeout(
                SETTLE,
                recv_with_fds(
                    &self.stream,
                    &mut self.scratch,
                    &mut self.buf,
                    &mut self.fds,
                ),
            )
            .await
            .context("nothing came from the hub in time")?;
            match read {
                Ok(0) => return Ok(None),
                Ok(_) => {}
                // A reset after the hub closed its side is a close too.
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => return Ok(None),
                Err(e) => return Err(e).context("reading"),
            }
        }
    }

    async fn request(&mut self, command: Command) -> anyhow::Result<Result<Reply, ErrorReply>> {
        let req = self.send(command).await?;
        until(&format!("the reply to request {req}"), SETTLE, async {
            loop {
                match self.next_event().await? {
                    Some(Event::Reply { req: r, result }) if r == req => return Ok(result),
                    Some(_) => {}
                    None => bail!("the hub closed the connection before answering request {req}"),
                }
            }
        })
        .await?
    }

    /// Every event until the hub closes the connection.
    async fn until_closed(&mut self) -> anyhow::Result<Vec<Event>> {
        let mut events = Vec::new();
        until("the hub to close the connection", SETTLE, async {
            while let Some(event) = self.next_event().await? {
                events.push(event);
            }
            anyhow::Ok(())
        })
        .await
        .with_context(|| format!("events so far: {events:?}"))??;
        Ok(events)
    }
}

#[tokio::test]
async fn a_session_that_did_not_log_in_cannot_get_a_segment() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    // A channel a stranger could name by id.
    let owner = agent.client("owner").await?;
    let theirs = owner.publisher("Shm.theirs", "{}").await?;
    let chan = theirs.id().context("no channel id")?;

    // Each shared-memory command as the first thing a connection says: refused, closed, no descriptor passed.
    for command in [
        Command::ShmOpen {
            chan,
            slot_size: 65536,
        },
        Command::ShmAccept,
    ] {
        let what = format!("{command:?} before login");
        let mut stranger = RawUnix::connect(&agent).await?;
        let req = stranger.send(command).await?;
        let events = stranger.until_closed().await.context(what.clone())?;
        for event in &events {
            if let Event::Reply { req: r, result } = event {
                assert_eq!(*r, req, "{what}: {events:?}");
                assert_eq!(
                    result.as_ref().err().map(|e| e.code),
                    Some(ErrorCode::NotAuthenticated),
                    "{what}: {events:?}"
                );
            }
        }
        assert!(
            stranger.fds.is_empty(),
            "{what}: the hub passed {} descriptor(s)",
            stranger.fds.len()
        );
    }
    assert_eq!(metric(&agent, "flow_shm_segments").await?, 0.0);
    assert_eq!(hub_memfds(&agent)?, Memfds { maps: 0, fds: 0 });

    // Logged in, a session gets no segment for someone else's channel either...
    let mut session = RawUnix::login(&agent).await?;
    let accepted = session.request(Command::ShmAccept).await?;
    assert!(
        matches!(accepted, Ok(Reply::Shm { threshold }) if threshold as usize == THRESHOLD),
        "{accepted:?}"
    );
    let refused = session
        .request(Command::ShmOpen {
            chan,
            slot_size: 65536,
        })
        .await?;
    assert_eq!(
        refused.as_ref().err().map(|e| e.code),
        Some(ErrorCode::NotOwner),
        "{refused:?}"
    );
    assert!(session.fds.is_empty(), "a descriptor came with a refusal");
    // ...but one for its own, with its descriptor beside the reply: the way the refusals were read sees one.
    let own = session
        .request(Command::AddChannel {
            kind: ChannelKind::Stream,
            name: "Shm.own".into(),
            header: "{}".into(),
        })
        .await?;
    let Ok(Reply::Channel(own)) = own else {
        bail!("creating a channel: {own:?}");
    };
    let segment = session
        .request(Command::ShmOpen {
            chan: own.id,
            slot_size: 65536,
        })
        .await?;
    assert!(
        matches!(segment, Ok(Reply::Segment(info)) if info.chan == own.id && info.slot_size >= 65536),
        "{segment:?}"
    );
    assert_eq!(
        session.fds.len(),
        1,
        "the segment's descriptor did not come"
    );
    until_metric(&agent, "flow_shm_segments", "1", |v| v == 1.0).await?;
    // The session leaves: its segment goes with it.
    drop(session);
    until_metric(&agent, "flow_shm_segments", "0", |v| v == 0.0).await?;
    until_memfds(&agent, "none", |m| m.total() == 0).await?;
    drop(theirs);
    Ok(())
}

#[tokio::test]
async fn a_subscriber_gives_its_slots_back_through_its_release_ring_and_none_is_left_held()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let producer = agent.unix_client("producer").await?;
    let reader = agent.unix_client("ring-sub").await?;
    let publisher = producer.publisher("Shm.ring", "{}").await?;
    let sub = reader.subscribe("Shm.ring").await?;
    until_subscribed(&publisher).await?;
    until_by_reference(&publisher, &sub, &[], 64 * 1024).await?;
    until_rings(&agent, 1).await?;

    // 300 messages, each dropped as it comes: every slot goes back, most of them through the ring. (The stream
    // numbers its messages from 1 again, past the channel's sequence, so they are not checked against it.)
    let (mut seen, task) = consume(sub, false);
    let streamer = stream(publisher, 64 * 1024, Duration::from_millis(1));
    until_count(&mut seen, 300, "the subscriber").await?;
    let (publisher, sent) = streamer.finish().await?;
    until_count(&mut seen, sent, "the subscriber's last message").await?;
    until_metric(&agent, "flow_shm_slots_held", "0", |v| v == 0.0).await?;
    let by_ring = metric_with(&agent, "flow_shm_released_total", "via=\"ring\"").await?;
    let by_frame = metric_with(&agent, "flow_shm_released_total", "via=\"frame\"").await?;
    println!("{sent} sent: {by_ring} slots given back through the ring, {by_frame} in frames");
    assert!(
        by_ring > 0.0,
        "no slot came back through the ring ({by_frame} in frames)"
    );
    check_consumer(task).await?;
    drop(publisher);
    // The subscriber's connection ends: its ring goes with it.
    reader.close_and_wait(PATIENCE).await;
    until_rings(&agent, 0).await?;
    Ok(())
}

/// A raw subscriber on the Unix socket, after `ShmAccept` and `Subscribe` of `chan`.
async fn raw_subscriber(agent: &Agent, chan: &str) -> anyhow::Result<RawUnix> {
    let mut raw = RawUnix::login(agent).await?;
    let accepted = raw.request(Command::ShmAccept).await?;
    anyhow::ensure!(accepted.is_ok(), "ShmAccept: {accepted:?}");
    let subscribed = raw
        .request(Command::Subscribe {
            chan: ChanRef::Name(chan.into()),
        })
        .await?;
    anyhow::ensure!(subscribed.is_ok(), "Subscribe: {subscribed:?}");
    Ok(raw)
}

/// Publishes numbered 64 KB messages one at a time until one reaches `raw` by reference (the SDK sends a channel's
/// first large message inline while it asks for its segment); that message's ring (from the descriptor beside
/// `ReleaseRing`) and slot.
async fn raw_by_reference(
    publisher: &Publisher,
    raw: &mut RawUnix,
) -> anyhow::Result<(OwnedFd, u32, SlotRef)> {
    let mut ring = None;
    until("a message by reference", SETTLE, async {
        for n in 1..=1000 {
            publisher.publish(numbered(n, 64 * 1024)).await?;
            loop {
                match raw.next_event().await? {
                    Some(Event::ReleaseRing { capacity }) => {
                        let fd = raw
                            .fds
                            .pop_front()
                            .context("the ring came without its descriptor")?;
                        ring = Some((fd, capacity));
                    }
                    Some(Event::Segment(_)) => {
                        raw.fds
                            .pop_front()
                            .context("a segment came without its descriptor")?;
                    }
                    Some(Event::DataRef { slot, .. }) => {
                        let (fd, capacity) = ring
                            .take()
                            .context("a message by reference before the ring")?;
                        return Ok((fd, capacity, slot));
                    }
                    Some(Event::Data { .. }) => break,
                    Some(_) => {}
                    None => bail!("the hub closed the connection"),
                }
            }
        }
        bail!("1000 messages and none came by reference")
    })
    .await?
}

#[tokio::test]
async fn a_release_written_into_the_ring_frees_the_slot_without_a_frame_and_a_broken_ring_closes_the_connection()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let producer = agent.unix_client("producer").await?;
    let publisher = producer.publisher("Shm.raw", "{}").await?;
    let mut raw = raw_subscriber(&agent, "Shm.raw").await?;
    until_subscribed(&publisher).await?;
    let (fd, capacity, slot) = raw_by_reference(&publisher, &mut raw).await?;
    until_metric(&agent, "flow_shm_slots_held", "1", |v| v == 1.0).await?;

    // Written into the ring: the hub frees the slot. If its writer was already idle it asked to be rung, and an
    // empty Release rings it; otherwise its writer takes the release when it goes idle. Either way no frame names
    // the slot.
    let mut ring = RingWriter::open(fd.try_clone()?, capacity)?;
    if ring.push(slot.segment, slot.slot) == Pushed::Ring {
        raw.send(Command::Release { slots: Vec::new() }).await?;
    }
    until_metric(&agent, "flow_shm_slots_held", "0", |v| v == 0.0).await?;
    assert_eq!(
        metric_with(&agent, "flow_shm_released_total", "via=\"ring\"").await?,
        1.0
    );
    assert_eq!(
        metric_with(&agent, "flow_shm_released_total", "via=\"frame\"").await?,
        0.0
    );

    // A head written far past what the hub took is a broken protocol: the connection closes, the hub goes on.
    let scribble = Mapping::open(fd, ring::ring_len(capacity), true)?;
    scribble
        .word(64)
        .context("the ring's head")?
        .store(capacity * 3, std::sync::atomic::Ordering::Release);
    raw.send(Command::Release { slots: Vec::new() }).await?;
    raw.until_closed().await?;
    until_rings(&agent, 0).await?;
    let mut other = raw_subscriber(&agent, "Shm.raw").await?;
    let after = raw_by_reference(&publisher, &mut other).await?;
    assert_eq!(after.1, capacity);
    Ok(())
}
