//! FlowProtocol over UDP through a real `flow-hub` (`server.flow_udp`): a satellite over UDP publishes to a TCP
//! subscriber and subscribes to a TCP publisher, intact; through a relay that drops 5%, reorders and duplicates
//! datagrams every service call is answered exactly once, every pair-database write lands, every delivered stream
//! message is intact and the lost ones are counted; a flood of garbage, spoofed datagrams and hellos gets no
//! answer (hellos: no more than they brought) and holds the hub to a bounded number of sessions.

use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent_tests::metrics::{parse, scrape, value};
use agent_tests::wires::{check, hub_with_udp, payload};
use agent_tests::{Agent, DataDir, PATIENCE};
use anyhow::{Context, ensure};
use bytes::Bytes;
use flow::transport::udp::datagram::{Datagram, HELLO_MIN, Kind};
use flow::{Client, FlowAddr, Subscription};
use rand::{Rng, SeedableRng};
use tokio::net::UdpSocket;

async fn udp_client(hub: &Agent, addr: SocketAddr, name: &str) -> anyhow::Result<Client> {
    Ok(Client::connect(&FlowAddr::Udp(addr.to_string()), hub.options(name)).await?)
}

async fn next(sub: &Subscription) -> anyhow::Result<Vec<u8>> {
    let data = tokio::time::timeout(PATIENCE, sub.recv())
        .await
        .context("no message")?
        .context("subscription ended")?;
    Ok(data.payload.to_vec())
}

async fn metric(hub: &Agent, name: &str) -> anyhow::Result<f64> {
    let samples = parse(&scrape(hub).await?).await?;
    value(&samples, name, &[]).with_context(|| format!("no {name} on /metrics"))
}

/// Collects every message of `sub` in the background: the sequence numbers of intact payloads, and how many were
/// damaged.
fn collect(sub: Subscription) -> (Arc<Mutex<Vec<u32>>>, Arc<AtomicU64>) {
    let (seen, damaged) = (
        Arc::new(Mutex::new(Vec::new())),
        Arc::new(AtomicU64::new(0)),
    );
    let (s, d) = (seen.clone(), damaged.clone());
    tokio::spawn(async move {
        while let Some(data) = sub.recv().await {
            match check(&data.payload) {
                Ok(seq) => s.lock().expect("seen").push(seq),
                Err(_) => {
                    d.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    });
    (seen, damaged)
}

fn seen(list: &Arc<Mutex<Vec<u32>>>) -> Vec<u32> {
    list.lock().expect("seen").clone()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_satellite_over_udp_publishes_to_a_tcp_subscriber_and_hears_a_tcp_publisher_intact()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let (hub, udp) = hub_with_udp(&dir, "").await?;
    let satellite = udp_client(&hub, udp, "udp-sat").await?;
    let watcher = hub.client("watcher").await?;
    // Single datagrams and frames of many fragments, both ways.
    let sizes = [8usize, 100, 1000, 5000, 20_000];
    let publisher = satellite
        .publisher("Udp.samples", r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let sub = watcher.subscribe("Udp.samples").await?;
    for seq in 0..50u32 {
        publisher
            .publish(payload(seq, sizes[seq as usize % sizes.len()]))
            .await?;
        // Paced: a burst larger than a socket buffer would be lost (and counted), which is not this test's point.
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    for expected in 0..50u32 {
        let p = next(&sub).await?;
        assert_eq!(check(&p)?, expected);
        assert_eq!(p.len(), 8 + sizes[expected as usize % sizes.len()]);
    }
    let tcp_publisher = watcher
        .publisher("Tcp.samples", r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let udp_sub = satellite.subscribe("Tcp.samples").await?;
    let mut active = tcp_publisher.subscribers();
    tokio::time::timeout(PATIENCE, active.wait_for(|&a| a))
        .await
        .context("the UDP subscription never reached the publisher")??;
    for seq in 0..50u32 {
        tcp_publisher
            .publish(payload(seq, sizes[seq as usize % sizes.len()]))
            .await?;
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    for expected in 0..50u32 {
        assert_eq!(check(&next(&udp_sub).await?)?, expected);
    }
    ensure!(metric(&hub, "flow_udp_lost_messages_total").await? == 0.0);
    satellite.close_and_wait(Duration::from_secs(5)).await;
    Ok(())
}

/// A picture channel `name` published by `from` and subscribed to by `to`, once the publisher knows of the
/// subscriber (what it publishes next reaches it).
async fn pictures(
    from: &Client,
    to: &Client,
    name: &str,
) -> anyhow::Result<(flow::Publisher, Subscription)> {
    let publisher = from.publisher(name, r#"{"mime":"image/jpeg"}"#).await?;
    let sub = to.subscribe(name).await?;
    let mut active = publisher.subscribers();
    tokio::time::timeout(PATIENCE, active.wait_for(|&a| a))
        .await
        .with_context(|| format!("the subscription to {name} never reached its publisher"))??;
    Ok((publisher, sub))
}

/// Pictures sent to a UDP subscriber leave the hub a burst at a time: each 60 kB frame's fragments go out in one
/// call (a segmented send, or `sendmmsg`), so the hub makes several times fewer send calls than it sends datagrams,
/// and every frame arrives whole and in order. Pictures a UDP publisher sends arrive at the hub in batches too: its
/// edge makes several times fewer receive calls than it receives datagrams.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_burst_of_pictures_to_a_udp_subscriber_leaves_in_batched_calls_and_arrives_whole_in_order()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let (hub, udp) = hub_with_udp(&dir, "").await?;
    let satellite = udp_client(&hub, udp, "udp-eyes").await?;
    let camera = hub.client("camera").await?;
    let (publisher, sub) = pictures(&camera, &satellite, "Udp.pictures").await?;
    let sent_before = metric(&hub, "flow_udp_sent_datagrams_total").await?;
    let calls_before = metric(&hub, "flow_udp_send_calls_total").await?;
    for seq in 0..20u32 {
        publisher.publish(payload(seq, 60_000)).await?;
        // A camera's pace, well within the socket buffers.
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    for expected in 0..20u32 {
        let p = next(&sub).await?;
        assert_eq!(check(&p)?, expected);
        assert_eq!(p.len(), 8 + 60_000);
    }
    let sent = metric(&hub, "flow_udp_sent_datagrams_total").await? - sent_before;
    let calls = metric(&hub, "flow_udp_send_calls_total").await? - calls_before;
    // 20 pictures of about 44 fragments each: at least 880 datagrams, in a few dozen calls.
    ensure!(sent >= 20.0 * 40.0, "{sent} datagrams sent");
    ensure!(
        calls * 4.0 <= sent,
        "{calls} send calls for {sent} datagrams: not batched"
    );

    // The other way: the satellite publishes pictures over UDP to a TCP subscriber.
    let (back, back_sub) = pictures(&satellite, &camera, "Udp.back").await?;
    let received_before = metric(&hub, "flow_udp_received_datagrams_total").await?;
    let receives_before = metric(&hub, "flow_udp_receive_calls_total").await?;
    for seq in 0..20u32 {
        back.publish(payload(seq, 60_000)).await?;
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    for expected in 0..20u32 {
        assert_eq!(check(&next(&back_sub).await?)?, expected);
    }
    let received = metric(&hub, "flow_udp_received_datagrams_total").await? - received_before;
    let receives = metric(&hub, "flow_udp_receive_calls_total").await? - receives_before;
    println!("the hub sent {sent} datagrams in {calls} calls, received {received} in {receives}");
    ensure!(received >= 20.0 * 40.0, "{received} datagrams received");
    ensure!(
        receives * 4.0 <= received,
        "{receives} receive calls for {received} datagrams: not batched"
    );
    ensure!(metric(&hub, "flow_udp_lost_messages_total").await? == 0.0);
    satellite.close_and_wait(Duration::from_secs(5)).await;
    Ok(())
}

/// What the relay did.
#[derive(Debug, Default)]
struct Mangled {
    dropped: AtomicU64,
    duplicated: AtomicU64,
    reordered: AtomicU64,
}

/// A UDP relay in front of `hub` that drops 5% of the datagrams each way, duplicates 5% and holds back 10% until
/// the next one has passed. Clients talk to its address.
async fn lossy_relay(hub: SocketAddr) -> anyhow::Result<(SocketAddr, Arc<Mangled>)> {
    let front = Arc::new(UdpSocket::bind("127.0.0.1:0").await?);
    let back = Arc::new(UdpSocket::bind("127.0.0.1:0").await?);
    back.connect(hub).await?;
    let addr = front.local_addr()?;
    let mangled = Arc::new(Mangled::default());
    let client: Arc<Mutex<Option<SocketAddr>>> = Arc::default();
    {
        let (front, back, mangled, client) =
            (front.clone(), back.clone(), mangled.clone(), client.clone());
        tokio::spawn(async move {
            let mut rng = rand::rngs::StdRng::seed_from_u64(38);
            let mut held = None;
            let mut buf = vec![0u8; 65536];
            while let Ok((n, from)) = front.recv_from(&mut buf).await {
                *client.lock().expect("client") = Some(from);
                for d in mangle(&mut rng, &mut held, buf[..n].to_vec(), &mangled) {
                    let _ = back.send(&d).await;
                }
            }
        });
    }
    {
        let mangled = mangled.clone();
        tokio::spawn(async move {
            let mut rng = rand::rngs::StdRng::seed_from_u64(83);
            let mut held = None;
            let mut buf = vec![0u8; 65536];
            while let Ok(n) = back.recv(&mut buf).await {
                let Some(to) = *client.lock().expect("client") else {
                    continue;
                };
                for d in mangle(&mut rng, &mut held, buf[..n].to_vec(), &mangled) {
                    let _ = front.send_to(&d, to).await;
                }
            }
        });
    }
    Ok((addr, mangled))
}

/// What goes on for one datagram `d`: nothing, itself, itself twice, or the one held back before it too.
fn mangle(rng: &mut impl Rng, held: &mut Option<Vec<u8>>, d: Vec<u8>, m: &Mangled) -> Vec<Vec<u8>> {
    if rng.random_bool(0.05) {
        m.dropped.fetch_add(1, Ordering::Relaxed);
        return Vec::new();
    }
    if held.is_none() && rng.random_bool(0.1) {
        m.reordered.fetch_add(1, Ordering::Relaxed);
        *held = Some(d);
        return Vec::new();
    }
    let mut out = vec![d.clone()];
    if rng.random_bool(0.05) {
        m.duplicated.fetch_add(1, Ordering::Relaxed);
        out.push(d);
    }
    out.extend(held.take());
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn through_a_lossy_relay_calls_are_answered_once_and_stream_messages_arrive_intact_or_counted_lost()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let (hub, udp) = hub_with_udp(&dir, "").await?;
    let (relay, mangled) = lossy_relay(udp).await?;
    // A TCP satellite serves calls and counts each request it gets.
    let server = hub.client("server").await?;
    let mut service = server.serve("Udp.echo", r#"{"kind":"echo"}"#).await?;
    let handled: Arc<Mutex<HashMap<Vec<u8>, u32>>> = Arc::default();
    {
        let handled = handled.clone();
        tokio::spawn(async move {
            while let Some(call) = service.next().await {
                *handled
                    .lock()
                    .expect("handled")
                    .entry(call.payload.to_vec())
                    .or_default() += 1;
                let mut answer = b"echo:".to_vec();
                answer.extend_from_slice(&call.payload);
                let _ = call.respond(Ok(Bytes::from(answer))).await;
            }
        });
    }
    let satellite = udp_client(&hub, relay, "udp-sat").await?;
    const CALLS: u32 = 200;
    for i in 0..CALLS {
        // Some requests span several datagrams.
        let mut request = format!("call {i} ").into_bytes();
        request.resize(if i % 10 == 0 { 4000 } else { request.len() }, b'.');
        let answer = satellite
            .call("Udp.echo", request.clone(), Duration::from_secs(20))
            .await
            .with_context(|| format!("call {i}"))?;
        ensure!(
            answer[..] == [b"echo:".as_slice(), &request].concat()[..],
            "call {i} answered wrong"
        );
    }
    {
        let handled = handled.lock().expect("handled");
        ensure!(
            handled.len() == CALLS as usize,
            "{} distinct requests reached the service",
            handled.len()
        );
        ensure!(
            handled.values().all(|&n| n == 1),
            "a request reached the service twice"
        );
    }
    // Pair-database writes are reliable too.
    for i in 0..20 {
        satellite
            .var_set(&format!("udp.key{i}"), &serde_json::json!({ "i": i }))
            .await?;
    }
    let watcher = hub.client("watcher").await?;
    for i in 0..20 {
        ensure!(
            watcher.var_get(&format!("udp.key{i}")).await? == Some(serde_json::json!({ "i": i }))
        );
    }
    // Stream data is best effort: 3 datagrams per message, some lose one, none arrives damaged.
    let publisher = satellite
        .publisher("Udp.samples", r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let (got, damaged) = collect(watcher.subscribe("Udp.samples").await?);
    const SENT: u32 = 300;
    for seq in 0..SENT {
        publisher.publish(payload(seq, 3000)).await?;
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    // Later messages push the hub's window past the last of them, so that each is delivered or counted lost.
    let mut filler = SENT;
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let (delivered, lost) = loop {
        let delivered = seen(&got).iter().filter(|&&s| s < SENT).count() as u64;
        let lost = metric(&hub, "flow_udp_lost_messages_total").await? as u64;
        if delivered + lost >= u64::from(SENT) || tokio::time::Instant::now() >= deadline {
            break (delivered, lost);
        }
        for _ in 0..10 {
            publisher.publish(payload(filler, 16)).await?;
            filler += 1;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    let list: Vec<u32> = seen(&got).into_iter().filter(|&s| s < SENT).collect();
    println!(
        "relay: {:?}; {delivered} of {SENT} delivered, {lost} counted lost, {} fragments asked for again",
        mangled,
        metric(&hub, "flow_udp_nacks_total").await?
    );
    ensure!(
        mangled.dropped.load(Ordering::Relaxed) > 0
            && mangled.duplicated.load(Ordering::Relaxed) > 0
    );
    ensure!(
        damaged.load(Ordering::Relaxed) == 0,
        "a damaged message was delivered"
    );
    ensure!(
        list.iter().collect::<HashSet<_>>().len() == list.len(),
        "a message was delivered twice"
    );
    // Messages of three datagrams that lost one were asked for again (or, past three asks, counted lost).
    ensure!(
        metric(&hub, "flow_udp_nacks_total").await? > 0.0,
        "5% loss never made the hub ask for a missing fragment"
    );
    ensure!(
        delivered + lost >= u64::from(SENT),
        "{delivered} delivered and {lost} counted of {SENT}"
    );
    ensure!(delivered > 0);
    ensure!(metric(&hub, "flow_udp_retransmitted_datagrams_total").await? > 0.0);
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_garbage_spoofed_datagrams_and_hellos_gets_nothing_and_bounded_sessions()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    // Strangers are held by the table (8 places), not by a login deadline that would clear them anyway.
    let (hub, udp) = hub_with_udp(
        &dir,
        "[hub]\nlogin_timeout_ms = 60000\nmax_unauthenticated = 8\n",
    )
    .await?;
    let attacker = UdpSocket::bind("127.0.0.1:0").await?;
    attacker.connect(udp).await?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let mut sent = 0u64;
    for i in 0..3000u32 {
        let d = match i % 3 {
            // Random bytes.
            0 => (0..rng.random_range(0..1500))
                .map(|_| rng.random())
                .collect::<Vec<u8>>(),
            // Well-formed datagrams of sessions that do not exist.
            1 => Datagram {
                kind: Kind::Reliable,
                session: rng.random(),
                seq: rng.random(),
                frag: 0,
                frags: 1,
                payload: &[1, 0, 0, 0, 1, 0, 0, 0, 0],
            }
            .to_vec(),
            // Hellos too short to be answered without amplification.
            _ => {
                let mut hello = Datagram::bare(Kind::Hello, rng.random(), 0).to_vec();
                hello.truncate(100);
                hello
            }
        };
        attacker.send(&d).await?;
        sent += 1;
        if i % 100 == 0 {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    }
    let mut buf = vec![0u8; 65536];
    let answer = tokio::time::timeout(Duration::from_millis(500), attacker.recv(&mut buf)).await;
    ensure!(answer.is_err(), "the flood got an answer: {answer:?}");
    let refused = metric(&hub, "flow_udp_malformed_datagrams_total").await?
        + metric(&hub, "flow_udp_spoofed_datagrams_total").await?;
    ensure!(
        refused > 0.0 && refused <= sent as f64,
        "{refused} refused of {sent}"
    );
    // A hello flood from many sockets: each answer is smaller than its hello, and the strangers' table keeps the
    // sessions bounded.
    let mut sockets = Vec::new();
    for _ in 0..100 {
        let s = UdpSocket::bind("127.0.0.1:0").await?;
        s.connect(udp).await?;
        s.send(&Datagram::bare(Kind::Hello, rng.random::<u32>() | 1, 0).to_vec())
            .await?;
        sockets.push(s);
    }
    for s in &sockets {
        if let Ok(Ok(n)) = tokio::time::timeout(Duration::from_millis(200), s.recv(&mut buf)).await
        {
            ensure!(
                n <= HELLO_MIN,
                "a {n}-byte answer to a {HELLO_MIN}-byte hello"
            );
        }
    }
    let deadline = tokio::time::Instant::now() + PATIENCE;
    loop {
        let sessions = metric(&hub, "flow_udp_sessions").await?;
        if sessions <= 8.0 {
            break;
        }
        ensure!(
            tokio::time::Instant::now() < deadline,
            "{sessions} sessions after a flood of hellos"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // The hub still serves a real client.
    let satellite = udp_client(&hub, udp, "after-the-flood").await?;
    satellite.ping().await?;
    Ok(())
}
