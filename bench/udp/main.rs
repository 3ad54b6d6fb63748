//! `udp-bench`: FlowProtocol over UDP against TCP in the same run (issue 38): 50 Hz PCM and 15 fps JPEG latency
//! p50/p99 and delivered / sent, and a flat-out JPEG burst, over TCP, over UDP direct, and over UDP through a relay
//! that drops a share (default 5%) of the datagrams in each direction.
//!
//! One `flow-hub` (found as the tests find it: `$AGENT_BIN_DIR/flow-hub`) with its UDP edge (`server.flow_udp`) on
//! a free port. For each link a publisher satellite and a subscriber satellite connect over that link; the publisher
//! sends 882-byte PCM blocks (20 ms of 22050 Hz s16 mono) at 50 Hz and the 640x360 JPEG fixture at 15 fps, both at
//! once, for `--seconds`, then one more second that is not counted (it keeps the best-effort lane moving past the
//! last counted message, so that each of them is delivered or lost, not left half-assembled). Every payload carries
//! `seq u64 | sent ns u64` over its first 16 bytes; publisher and subscriber are tasks of this one process, so one
//! monotonic clock serves both ends and a latency is a subtraction. The burst publishes the JPEG as fast as the SDK
//! takes it for `--burst-seconds` and counts what arrives.
//!
//! TCP is not measured under loss: that needs `tc qdisc ... netem`, and this machine has no netem kernel module.
//! The lossy UDP figures are therefore compared against TCP at 0% loss.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use agent_bench::percentile;
use agent_tests::{Agent, DataDir, PATIENCE, until_subscribed};
use anyhow::{Context, ensure};
use bytes::Bytes;
use clap::Parser;
use flow::{Client, FlowAddr, Publisher, Subscription};
use tokio::net::UdpSocket;
use tokio::time::MissedTickBehavior;

#[derive(Debug, Parser)]
#[command(
    about = "FlowProtocol over UDP against TCP: fixed-rate latency, delivery under loss, a flat-out burst"
)]
struct Args {
    /// Seconds each link carries the fixed-rate PCM and JPEG streams.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Seconds of the flat-out JPEG burst on each link.
    #[arg(long, default_value_t = 2.0)]
    burst_seconds: f64,
    /// Share of the datagrams the relay drops, in each direction.
    #[arg(long, default_value_t = 0.05)]
    loss: f64,
    /// Fixtures directory [default: $AGENT_FIXTURES or ../shared/fixtures beside the repo]
    #[arg(long)]
    fixtures: Option<PathBuf>,
}

/// What the fixed-rate stream targets ask of the lossy link: this share of the JPEG frames delivered.
const JPEG_DELIVERY_TARGET: f64 = 0.85;

/// How long a subscriber keeps listening after the last message was sent: a lost fragment's recovery or a
/// retransmission may still be under way.
const GRACE: Duration = Duration::from_secs(1);

/// Bytes the stamp takes at the start of a payload: `seq u64 LE | sent_ns u64 LE`.
const STAMP: usize = 16;

fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

/// Nanoseconds on the process-wide monotonic clock.
fn clock_ns() -> u64 {
    // A run lasts minutes, far from the 584 years a u64 of nanoseconds holds.
    epoch().elapsed().as_nanos() as u64
}

/// `template` with `seq` and the current time over its first bytes, so the size under test is the template's.
fn stamped(template: &[u8], seq: u64) -> Bytes {
    let mut p = template.to_vec();
    p[..8].copy_from_slice(&seq.to_le_bytes());
    p[8..STAMP].copy_from_slice(&clock_ns().to_le_bytes());
    Bytes::from(p)
}

/// `(seq, sent_ns)` of a received payload; `None` if too short to carry a stamp.
fn read_stamp(p: &[u8]) -> Option<(u64, u64)> {
    let seq = u64::from_le_bytes(p.get(..8)?.try_into().ok()?);
    let sent = u64::from_le_bytes(p.get(8..STAMP)?.try_into().ok()?);
    Some((seq, sent))
}

/// The three links measured, in the order they run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Link {
    Tcp,
    Udp,
    Lossy,
}

impl Link {
    fn key(self) -> &'static str {
        match self {
            Link::Tcp => "tcp",
            Link::Udp => "udp",
            Link::Lossy => "udp-lossy",
        }
    }
}

/// One stream's figures on one link.
#[derive(Debug, Clone, Default)]
struct Outcome {
    sent: u64,
    /// Distinct counted messages that arrived.
    delivered: u64,
    /// Latency of each delivered message, ms.
    latencies: Vec<f64>,
    /// Arrivals of the wrong size (a transport that corrupted a message).
    damaged: u64,
    /// What the subscriber's own drop-oldest queue dropped.
    queue_dropped: u64,
}

impl Outcome {
    fn p(&self, q: f64) -> f64 {
        percentile(&self.latencies, q)
    }

    fn share(&self) -> f64 {
        if self.sent == 0 {
            f64::NAN
        } else {
            self.delivered as f64 / self.sent as f64
        }
    }

    fn line(&self) -> String {
        format!(
            "sent {} delivered {} ({:.1}%), p50 {} ms p99 {} ms max {} ms, damaged {}, dropped by the subscriber's queue {}",
            self.sent,
            self.delivered,
            100.0 * self.share(),
            ms(self.p(0.5)),
            ms(self.p(0.99)),
            ms(self.p(1.0)),
            self.damaged,
            self.queue_dropped
        )
    }
}

/// A link's figures.
#[derive(Debug, Clone, Default)]
struct LinkResult {
    pcm: Outcome,
    jpeg: Outcome,
    burst: Outcome,
    burst_seconds: f64,
    /// Bytes of each burst message.
    burst_bytes: usize,
}

fn ms(v: f64) -> String {
    if v.is_nan() {
        "n/a".into()
    } else {
        format!("{v:.2}")
    }
}

/// Collects `sub`'s messages until `until`: first arrival per sequence number with its latency.
fn listen(
    sub: Subscription,
    size: usize,
    until: tokio::time::Instant,
) -> tokio::task::JoinHandle<(HashMap<u64, f64>, u64, u64)> {
    tokio::spawn(async move {
        let mut heard = HashMap::new();
        let mut damaged = 0;
        while let Ok(Some(data)) = tokio::time::timeout_at(until, sub.recv()).await {
            let now = clock_ns();
            match read_stamp(&data.payload) {
                Some((seq, sent)) if data.payload.len() == size => {
                    heard
                        .entry(seq)
                        .or_insert(now.saturating_sub(sent) as f64 / 1e6);
                }
                _ => damaged += 1,
            }
        }
        (heard, damaged, sub.dropped())
    })
}

/// The outcome of the first `sent` messages of what a listener heard.
fn outcome(sent: u64, (heard, damaged, queue_dropped): (HashMap<u64, f64>, u64, u64)) -> Outcome {
    let latencies: Vec<f64> = heard
        .into_iter()
        .filter(|&(seq, _)| seq < sent)
        .map(|(_, l)| l)
        .collect();
    Outcome {
        sent,
        delivered: latencies.len() as u64,
        latencies,
        damaged,
        queue_dropped,
    }
}

/// A publisher on `channel` from `sender` and a subscription to it from `receiver`, once the hub has joined them.
async fn pair(
    sender: &Client,
    receiver: &Client,
    channel: &str,
) -> anyhow::Result<(Publisher, Subscription)> {
    let publisher = sender
        .publisher(channel, r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let sub = receiver.subscribe(channel).await?;
    until_subscribed(&publisher).await?;
    Ok((publisher, sub))
}

/// `template` at `hz` for `seconds` (counted), then one second more (not counted).
async fn fixed_rate(
    sender: &Client,
    receiver: &Client,
    channel: &str,
    template: &[u8],
    hz: f64,
    seconds: f64,
) -> anyhow::Result<Outcome> {
    let (publisher, sub) = pair(sender, receiver, channel).await?;
    let counted = (seconds * hz).round() as u64;
    let tail = hz.ceil() as u64;
    let period = Duration::from_secs_f64(1.0 / hz);
    let until = tokio::time::Instant::now() + period * (counted + tail) as u32 + GRACE;
    let listener = listen(sub, template.len(), until);
    let mut tick = tokio::time::interval(period);
    // A late tick is sent at once: the rate is kept on average, as a capture device's would be.
    tick.set_missed_tick_behavior(MissedTickBehavior::Burst);
    for seq in 0..counted + tail {
        tick.tick().await;
        publisher.publish(stamped(template, seq)).await?;
    }
    Ok(outcome(counted, listener.await?))
}

/// `template` as fast as the SDK takes it for `seconds`.
async fn burst(
    sender: &Client,
    receiver: &Client,
    channel: &str,
    template: &[u8],
    seconds: f64,
) -> anyhow::Result<Outcome> {
    let (publisher, sub) = pair(sender, receiver, channel).await?;
    let window = Duration::from_secs_f64(seconds);
    // A publish may wait on a full link, so the sending can end a little after the window.
    let until = tokio::time::Instant::now() + window + GRACE * 3;
    let listener = listen(sub, template.len(), until);
    let start = Instant::now();
    let mut seq = 0;
    while start.elapsed() < window {
        publisher.publish(stamped(template, seq)).await?;
        seq += 1;
    }
    Ok(outcome(seq, listener.await?))
}

/// What the relay did, both directions together.
#[derive(Debug, Default)]
struct Relayed {
    passed: AtomicU64,
    dropped: AtomicU64,
}

/// SplitMix64: a seeded, repeatable choice of which datagrams the relay drops (the bench has no `rand`).
#[derive(Debug)]
struct Dice(u64);

impl Dice {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// True with probability `p`.
    fn chance(&mut self, p: f64) -> bool {
        ((self.next() >> 11) as f64 / (1u64 << 53) as f64) < p
    }
}

/// A UDP relay in front of `hub` that drops `loss` of the datagrams each way. Every client address gets a socket of
/// its own towards the hub, so the hub sees one session per client as it would without the relay.
async fn lossy_relay(hub: SocketAddr, loss: f64) -> anyhow::Result<(SocketAddr, Arc<Relayed>)> {
    let front = Arc::new(UdpSocket::bind("127.0.0.1:0").await?);
    let addr = front.local_addr()?;
    let relayed = Arc::new(Relayed::default());
    let counts = relayed.clone();
    tokio::spawn(async move {
        let mut backs: HashMap<SocketAddr, Arc<UdpSocket>> = HashMap::new();
        let mut dice = Dice(38);
        let mut buf = vec![0u8; 65536];
        while let Ok((n, from)) = front.recv_from(&mut buf).await {
            let back = match backs.get(&from) {
                Some(back) => back.clone(),
                None => {
                    let Ok(back) = open_back(hub).await else {
                        continue;
                    };
                    let seed = 83 + backs.len() as u64;
                    tokio::spawn(towards_client(
                        back.clone(),
                        front.clone(),
                        from,
                        loss,
                        Dice(seed),
                        counts.clone(),
                    ));
                    backs.insert(from, back.clone());
                    back
                }
            };
            if dice.chance(loss) {
                counts.dropped.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            counts.passed.fetch_add(1, Ordering::Relaxed);
            let _ = back.send(&buf[..n]).await;
        }
    });
    Ok((addr, relayed))
}

async fn open_back(hub: SocketAddr) -> std::io::Result<Arc<UdpSocket>> {
    let back = UdpSocket::bind("127.0.0.1:0").await?;
    back.connect(hub).await?;
    Ok(Arc::new(back))
}

/// The hub's datagrams to one client, less the dropped ones.
async fn towards_client(
    back: Arc<UdpSocket>,
    front: Arc<UdpSocket>,
    client: SocketAddr,
    loss: f64,
    mut dice: Dice,
    counts: Arc<Relayed>,
) {
    let mut buf = vec![0u8; 65536];
    while let Ok(n) = back.recv(&mut buf).await {
        if dice.chance(loss) {
            counts.dropped.fetch_add(1, Ordering::Relaxed);
            continue;
        }
        counts.passed.fetch_add(1, Ordering::Relaxed);
        let _ = front.send_to(&buf[..n], client).await;
    }
}

/// A counter of the hub's `/metrics` (text exposition, `NAME VALUE` lines); NaN if it cannot be read, since the
/// counters only explain the figures and are not figures themselves.
async fn counter(hub: &Agent, name: &str) -> f64 {
    let Ok(text) = agent_tests::metrics::scrape(hub).await else {
        return f64::NAN;
    };
    text.lines()
        .filter_map(|l| l.strip_prefix(name))
        .filter_map(|rest| rest.strip_prefix(' '))
        .find_map(|v| v.trim().parse().ok())
        .unwrap_or(f64::NAN)
}

/// The hub's UDP counters that explain a lossy run.
async fn udp_counters(hub: &Agent) -> [f64; 3] {
    [
        counter(hub, "flow_udp_lost_messages_total").await,
        counter(hub, "flow_udp_retransmitted_datagrams_total").await,
        counter(hub, "flow_udp_dropped_datagrams_total").await,
    ]
}

/// The payloads: an 882-byte PCM block and the JPEG fixture.
struct Payloads {
    pcm: Vec<u8>,
    jpeg: Vec<u8>,
}

/// Runs one link: both fixed-rate streams at once, then the burst.
async fn run_link(
    hub: &Agent,
    addr: &FlowAddr,
    link: Link,
    payloads: &Payloads,
    args: &Args,
) -> anyhow::Result<LinkResult> {
    let key = link.key();
    let sender = Client::connect(addr, hub.options(&format!("pub-{key}"))).await?;
    let receiver = Client::connect(addr, hub.options(&format!("sub-{key}"))).await?;
    let (pcm_channel, jpeg_channel) = (format!("Bench.{key}.pcm"), format!("Bench.{key}.jpeg"));
    let (pcm, jpeg) = tokio::try_join!(
        fixed_rate(
            &sender,
            &receiver,
            &pcm_channel,
            &payloads.pcm,
            50.0,
            args.seconds
        ),
        fixed_rate(
            &sender,
            &receiver,
            &jpeg_channel,
            &payloads.jpeg,
            15.0,
            args.seconds
        ),
    )?;
    println!("{key} pcm 50 Hz: {}", pcm.line());
    println!("{key} jpeg 15 fps: {}", jpeg.line());
    let burst = burst(
        &sender,
        &receiver,
        &format!("Bench.{key}.burst"),
        &payloads.jpeg,
        args.burst_seconds,
    )
    .await?;
    println!("{key} jpeg burst: {}", burst.line());
    sender.close_and_wait(Duration::from_secs(2)).await;
    receiver.close_and_wait(Duration::from_secs(2)).await;
    Ok(LinkResult {
        pcm,
        jpeg,
        burst,
        burst_seconds: args.burst_seconds,
        burst_bytes: payloads.jpeg.len(),
    })
}

/// A link's run bounded in time, so a stalled link ends the bench's wait with an error instead of hanging; the
/// failure is printed and the link's figures are left empty.
async fn run_bounded(
    hub: &Agent,
    addr: &FlowAddr,
    link: Link,
    payloads: &Payloads,
    args: &Args,
) -> Option<LinkResult> {
    let limit = Duration::from_secs_f64(args.seconds + args.burst_seconds + 10.0) + PATIENCE * 2;
    match tokio::time::timeout(limit, run_link(hub, addr, link, payloads, args)).await {
        Ok(Ok(result)) => Some(result),
        Ok(Err(e)) => {
            println!("{}: failed: {e:#}", link.key());
            None
        }
        Err(_) => {
            println!("{}: did not finish within {limit:?}", link.key());
            None
        }
    }
}

fn met(ok: bool) -> &'static str {
    if ok { "met" } else { "missed" }
}

/// Messages per second and MB/s of a burst.
fn rate(r: &LinkResult) -> (f64, f64, f64) {
    let per_s = r.burst.delivered as f64 / r.burst_seconds;
    let sent_per_s = r.burst.sent as f64 / r.burst_seconds;
    (per_s, per_s * r.burst_bytes as f64 / 1e6, sent_per_s)
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    ensure!(
        args.seconds > 0.0 && args.burst_seconds > 0.0,
        "--seconds and --burst-seconds must be positive"
    );
    ensure!((0.0..1.0).contains(&args.loss), "--loss must be in [0, 1)");
    let fixtures = args
        .fixtures
        .clone()
        .unwrap_or_else(agent_tests::fixtures::fixtures);
    let jpeg_path = fixtures.join("faces/derived/fr_two_people_640x360.jpg");
    let jpeg =
        std::fs::read(&jpeg_path).with_context(|| format!("reading {}", jpeg_path.display()))?;
    ensure!(
        jpeg.len() > STAMP && jpeg.starts_with(&[0xff, 0xd8]),
        "{} is not a JPEG",
        jpeg_path.display()
    );
    // The bytes of a PCM block do not matter to a transport; its size does: 441 s16 samples.
    let pcm: Vec<u8> = (0..882u32).map(|i| (i * 37 % 251) as u8).collect();
    let payloads = Payloads { pcm, jpeg };
    epoch();

    let dir = DataDir::new()?;
    let (hub, udp) = agent_tests::wires::hub_with_udp(&dir, "").await?;
    let (relay, relayed) = lossy_relay(udp, args.loss).await?;
    let loss_pct = args.loss * 100.0;
    println!(
        "udp-bench: hub tcp://{} udp://{udp}, relay udp://{relay} dropping {loss_pct:.0}% of datagrams each way; \
         PCM {} bytes at 50 Hz and JPEG {} bytes at 15 fps for {} s per link, then a {} s flat-out JPEG burst",
        hub.flow_tcp,
        payloads.pcm.len(),
        payloads.jpeg.len(),
        args.seconds,
        args.burst_seconds
    );
    println!(
        "note: TCP is not measured under loss (no netem kernel module here: `tc qdisc ... netem` fails); \
         UDP at {loss_pct:.0}% loss is compared against TCP at 0%"
    );

    let tcp = run_bounded(&hub, &hub.tcp(), Link::Tcp, &payloads, &args).await;
    let calls = [
        "flow_udp_sent_datagrams_total",
        "flow_udp_send_calls_total",
        "flow_udp_received_datagrams_total",
        "flow_udp_receive_calls_total",
    ];
    let mut calls_before = [0.0; 4];
    for (value, name) in calls_before.iter_mut().zip(calls) {
        *value = counter(&hub, name).await;
    }
    let direct = run_bounded(
        &hub,
        &FlowAddr::Udp(udp.to_string()),
        Link::Udp,
        &payloads,
        &args,
    )
    .await;
    let mut calls_after = [0.0; 4];
    for (value, name) in calls_after.iter_mut().zip(calls) {
        *value = counter(&hub, name).await;
    }
    let d: Vec<f64> = calls_after
        .iter()
        .zip(calls_before)
        .map(|(a, b)| a - b)
        .collect();
    println!(
        "hub during the direct UDP run: sent {} datagrams in {} calls, received {} in {} calls",
        d[0], d[1], d[2], d[3]
    );
    let before = udp_counters(&hub).await;
    let lossy = run_bounded(
        &hub,
        &FlowAddr::Udp(relay.to_string()),
        Link::Lossy,
        &payloads,
        &args,
    )
    .await;
    let after = udp_counters(&hub).await;
    println!(
        "relay: {} datagrams passed, {} dropped; hub during the lossy run: {} messages counted lost, {} datagrams \
         retransmitted, {} datagrams dropped at the edge",
        relayed.passed.load(Ordering::Relaxed),
        relayed.dropped.load(Ordering::Relaxed),
        after[0] - before[0],
        after[1] - before[1],
        after[2] - before[2]
    );

    let empty = LinkResult::default();
    let (t, u, l) = (
        tcp.as_ref().unwrap_or(&empty),
        direct.as_ref().unwrap_or(&empty),
        lossy.as_ref().unwrap_or(&empty),
    );
    let fixed = |name: &str, pick: fn(&LinkResult) -> &Outcome| {
        let (t, u, l) = (pick(t), pick(u), pick(l));
        let ratio = u.p(0.99) / t.p(0.99);
        format!(
            "SUMMARY udp_{name}: p50 {} ms p99 {} ms, delivered {} of {} (TCP p50 {} ms p99 {} ms; p99 ratio {ratio:.2}, \
             target <= 1: {}) at 0% loss; at {loss_pct:.0}% loss p50 {} ms p99 {} ms, delivered {} of {} ({:.3})",
            ms(u.p(0.5)),
            ms(u.p(0.99)),
            u.delivered,
            u.sent,
            ms(t.p(0.5)),
            ms(t.p(0.99)),
            met(ratio <= 1.0),
            ms(l.p(0.5)),
            ms(l.p(0.99)),
            l.delivered,
            l.sent,
            l.share()
        )
    };
    println!("{}", fixed("pcm", |r| &r.pcm));
    println!("{}", fixed("jpeg", |r| &r.jpeg));
    let share = l.jpeg.share();
    println!(
        "SUMMARY udp_jpeg_loss: at {loss_pct:.0}% loss each way {} of {} JPEG frames delivered, {share:.3} \
         (target >= {JPEG_DELIVERY_TARGET}): {}; TCP not measured under loss (no netem), compared at 0%",
        l.jpeg.delivered,
        l.jpeg.sent,
        met(share >= JPEG_DELIVERY_TARGET)
    );
    let burst = |r: &LinkResult| {
        let (per_s, mb_s, sent_per_s) = rate(r);
        format!(
            "{per_s:.0} msgs/s ({mb_s:.1} MB/s) delivered of {sent_per_s:.0} sent/s ({:.3}), p99 {} ms",
            r.burst.share(),
            ms(r.burst.p(0.99))
        )
    };
    println!(
        "SUMMARY udp_throughput: flat-out 52 KB JPEG over UDP {}; over TCP {}; UDP at {loss_pct:.0}% loss {}",
        burst(u),
        burst(t),
        burst(l)
    );
    ensure!(
        tcp.is_some() && direct.is_some() && lossy.is_some(),
        "a link failed (see above)"
    );
    Ok(())
}
