//! Multi-process tests of the flow hub: a real `flow-hub` (the hub crate's binary, no agent modules) with satellites
//! over TCP, WebSocket and the Unix socket exchanging streams and service
//! calls; malformed frames and unauthenticated peers; slow subscribers; the
//! SDK's reconnection after the server is killed; the example satellites.
//!
//! Build the binaries first: `cargo build -p flow-hub -p flowctl -p flow-examples`.

use std::time::Duration;

use agent_tests::{
    Agent, AgentOptions, DataDir, PATIENCE, RawConn, command, fixture, http, recv, run, until,
    until_subscribed,
};
use anyhow::{Context, bail};
use bytes::{BufMut, Bytes, BytesMut};
use flow::protocol::{ChanRef, ChannelKind, Command, ErrorCode, Event, PROTOCOL_VERSION, op};
use flow::{Client, ClientEvent, FlowError};

/// Waits for an event matching `pick` on a client's event stream.
async fn until_event<T>(
    events: &mut tokio::sync::broadcast::Receiver<ClientEvent>,
    mut pick: impl FnMut(&ClientEvent) -> Option<T>,
) -> anyhow::Result<T> {
    tokio::time::timeout(PATIENCE, async {
        loop {
            match events.recv().await {
                Ok(e) => {
                    if let Some(v) = pick(&e) {
                        return Ok(v);
                    }
                }
                Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => continue,
                Err(e) => bail!("event stream ended: {e}"),
            }
        }
    })
    .await
    .context("the expected client event did not come")?
}

/// Answers every call on `name` with the request upper-cased.
async fn serve_upper(client: &Client, name: &str) -> anyhow::Result<tokio::task::JoinHandle<()>> {
    let mut service = client.serve(name, r#"{"kind":"upper"}"#).await?;
    Ok(tokio::spawn(async move {
        while let Some(call) = service.next().await {
            let upper = call.payload.to_ascii_uppercase();
            let _ = call.respond(Ok(Bytes::from(upper))).await;
        }
    }))
}

// ---------------------------------------------------------------- streams and services

#[tokio::test]
async fn satellites_over_tcp_and_websocket_exchange_streams_and_calls() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    // Deep queues: this test is about transports; thinning under bursts is tested below.
    let agent = Agent::hub_with_config(&dir, "[hub]\nsubscriber_queue = 4096\n").await?;
    let a = agent.client("sat-a").await?;
    let b = agent.client("sat-b").await?;
    let c = Client::connect(&agent.ws(), agent.options("sat-c")).await?;

    let pa = a
        .publisher("Sat.a", r#"{"mime":"application/octet-stream"}"#)
        .await?;
    let pc = c.publisher("Sat.c", r#"{"mime":"image/jpeg"}"#).await?;
    let _upper = serve_upper(&b, "Sat.b.upper").await?;
    assert!(!pa.has_subscribers());

    let b_on_a = b.subscribe("Sat.a").await?;
    let c_on_a = c.subscribe("Sat.a").await?;
    let a_on_c = a.subscribe("Sat.c").await?;
    until_subscribed(&pa).await?;
    until_subscribed(&pc).await?;

    // TCP -> TCP and TCP -> WebSocket: 300 messages of varied sizes, in order, complete.
    let sent: Vec<Bytes> = (0..300u32)
        .map(|i| {
            let mut v = i.to_le_bytes().to_vec();
            v.resize(4 + (i as usize * 97) % 5000, (i % 251) as u8);
            Bytes::from(v)
        })
        .collect();
    for p in &sent {
        pa.publish(p.clone()).await?;
    }
    for sub in [&b_on_a, &c_on_a] {
        for (i, expected) in sent.iter().enumerate() {
            let got = recv(sub).await?;
            assert_eq!(got.seq, i as u64 + 1, "{}", sub.name());
            assert_eq!(&got.payload, expected, "{} message {i}", sub.name());
        }
    }
    // WebSocket -> TCP with a real camera-sized JPEG.
    let jpeg = Bytes::from(std::fs::read(fixture(
        "faces/derived/fr_two_people_640x360.jpg",
    )?)?);
    for _ in 0..5 {
        pc.publish(jpeg.clone()).await?;
    }
    for n in 1..=5 {
        let got = recv(&a_on_c).await?;
        assert_eq!((got.seq, got.payload.len()), (n, jpeg.len()));
        assert_eq!(got.payload, jpeg);
    }
    assert_eq!(
        a_on_c.info().map(|i| i.header),
        Some(r#"{"mime":"image/jpeg"}"#.to_string())
    );

    // A synchronous call from the WebSocket satellite to the TCP one.
    let answer = c
        .call(
            "Sat.b.upper",
            &b"hello from ws"[..],
            Duration::from_secs(10),
        )
        .await?;
    assert_eq!(&answer[..], b"HELLO FROM WS");
    // Asynchronous calls: the answers arrive as events, matched by request id.
    let mut events = a.events();
    let first = a
        .call_async("Sat.b.upper", &b"one"[..], Duration::from_secs(10))
        .await?;
    let second = a
        .call_async("Sat.b.upper", &b"two"[..], Duration::from_secs(10))
        .await?;
    let mut answers = std::collections::HashMap::new();
    while answers.len() < 2 {
        let (req, result) = until_event(&mut events, |e| match e {
            ClientEvent::CallResult { req, result } => Some((*req, result.clone())),
            _ => None,
        })
        .await?;
        answers.insert(req, result?);
    }
    assert_eq!(&answers[&first][..], b"ONE");
    assert_eq!(&answers[&second][..], b"TWO");

    // Calls that cannot succeed fail with the hub's reason.
    let missing = c.call("No.such", &b"x"[..], Duration::from_secs(5)).await;
    assert_eq!(
        missing.expect_err("no service").code(),
        Some(ErrorCode::NotFound)
    );
    let wrong = c.call("Sat.a", &b"x"[..], Duration::from_secs(5)).await;
    assert_eq!(
        wrong.expect_err("a stream").code(),
        Some(ErrorCode::WrongKind)
    );
    // Publishing on someone else's channel is refused, by name lookup and by id.
    let listed = c.channels().await?;
    let names: Vec<_> = listed.iter().map(|i| (i.name.as_str(), i.kind)).collect();
    for expected in [
        ("Sat.a", ChannelKind::Stream),
        ("Sat.c", ChannelKind::Stream),
        ("Sat.b.upper", ChannelKind::Service),
    ] {
        assert!(names.contains(&expected), "{names:?}");
    }
    let refused = c.remove_channel("Sat.a").await;
    assert_eq!(
        refused.expect_err("not owner").code(),
        Some(ErrorCode::NotOwner)
    );

    // The HTTP API sees the same channels with their counters.
    let list = http::get_json(agent.http, "/api/channels", agent.token()).await?;
    let sat_a = list
        .as_array()
        .and_then(|l| l.iter().find(|c| c["name"] == "Sat.a"))
        .context("Sat.a missing from /api/channels")?;
    assert_eq!(sat_a["kind"], "stream");
    assert_eq!(sat_a["subscribers"], 2);
    assert_eq!(sat_a["msgs"], 300);
    assert!(
        sat_a["owner"]
            .as_str()
            .is_some_and(|o| o.starts_with("sat-a#"))
    );
    assert_eq!(
        http::get(agent.http, "/healthz").await?,
        (200, "ok".to_string())
    );
    Ok(())
}

#[tokio::test]
async fn a_satellite_on_the_unix_socket_talks_with_one_on_tcp() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let local = Client::connect(&agent.unix(), agent.options("unix-sat")).await?;
    let remote = agent.client("tcp-sat").await?;
    let publisher = local.publisher("Unix.data", "{}").await?;
    let sub = remote.subscribe("Unix.data").await?;
    let _svc = serve_upper(&local, "Unix.upper").await?;
    until_subscribed(&publisher).await?;
    for i in 0..50u8 {
        publisher.publish(vec![i; 100]).await?;
    }
    for i in 0..50u8 {
        assert_eq!(recv(&sub).await?.payload, vec![i; 100]);
    }
    let answer = remote
        .call("Unix.upper", &b"via unix"[..], Duration::from_secs(10))
        .await?;
    assert_eq!(&answer[..], b"VIA UNIX");
    // The database is shared across transports.
    local
        .var_set("unix.key", &serde_json::json!({"n": 1}))
        .await?;
    assert_eq!(
        remote.var_get("unix.key").await?,
        Some(serde_json::json!({"n": 1}))
    );
    Ok(())
}

#[tokio::test]
async fn calls_to_a_silent_or_vanished_service_fail_clearly() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let owner = agent.client("owner").await?;
    let caller = agent.client("caller").await?;
    let mut service = owner.serve("Silent.svc", "{}").await?;
    // Requests are handed to the test and kept unanswered (dropping one would answer it with an error).
    let (arrived_tx, mut arrived) = tokio::sync::mpsc::unbounded_channel();
    tokio::spawn(async move {
        while let Some(call) = service.next().await {
            if arrived_tx.send(call).is_err() {
                return;
            }
        }
    });
    let timed_out = caller
        .call("Silent.svc", &b"1"[..], Duration::from_millis(300))
        .await
        .expect_err("no answer");
    assert_eq!(timed_out.code(), Some(ErrorCode::Timeout), "{timed_out}");
    assert!(timed_out.to_string().contains("Silent.svc"), "{timed_out}");
    let first = tokio::time::timeout(PATIENCE, arrived.recv())
        .await
        .context("the first request never reached the owner")?
        .context("service ended")?;
    let mut held = vec![first];

    // A long call in flight when the owner disappears fails as "gone", not as a timeout.
    let pending = {
        let caller = caller.clone();
        tokio::spawn(async move {
            caller
                .call("Silent.svc", &b"2"[..], Duration::from_secs(120))
                .await
        })
    };
    let second = tokio::time::timeout(PATIENCE, arrived.recv())
        .await
        .context("the second request never reached the owner")?
        .context("service ended")?;
    assert_eq!(&second.payload[..], b"2");
    held.push(second);
    owner.close();
    let gone = tokio::time::timeout(PATIENCE, pending)
        .await
        .context("the pending call was not failed")??
        .expect_err("owner gone");
    assert_eq!(gone.code(), Some(ErrorCode::ServiceGone), "{gone}");
    drop(held);
    // Its channel went with it.
    let after = caller
        .call("Silent.svc", &b"3"[..], Duration::from_secs(5))
        .await;
    assert_eq!(
        after.expect_err("removed").code(),
        Some(ErrorCode::NotFound)
    );
    Ok(())
}

#[tokio::test]
async fn a_sticky_subscription_follows_a_channel_that_comes_and_goes() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let listener = agent.client("listener").await?;
    // Subscribing to a channel that does not exist yet is not an error.
    let sub = listener.subscribe("Late.data").await?;
    let first_owner = agent.client("first-owner").await?;
    let first = first_owner.publisher("Late.data", "{}").await?;
    until_subscribed(&first).await?;
    first.publish(&b"one"[..]).await?;
    assert_eq!(&recv(&sub).await?.payload[..], b"one");
    let first_id = first.id();
    // The channel goes away with its publisher, and comes back from someone else.
    let second_owner = agent.client("second-owner").await?;
    let mut seen = second_owner.events();
    drop(first);
    until_event(&mut seen, |e| {
        matches!(e, ClientEvent::ChannelRemoved { name, .. } if name == "Late.data").then_some(())
    })
    .await?;
    let second = second_owner.publisher("Late.data", "{\"v\":2}").await?;
    assert_ne!(second.id(), first_id, "the new channel reused the old id");
    until_subscribed(&second).await?;
    second.publish(&b"two"[..]).await?;
    let got = recv(&sub).await?;
    assert_eq!((&got.payload[..], got.seq), (&b"two"[..], 1));
    Ok(())
}

// ---------------------------------------------------------------- slow subscribers

#[tokio::test]
async fn a_subscriber_that_stops_reading_loses_old_data_while_another_gets_everything()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub_with_config(&dir, "[hub]\nsubscriber_queue = 16\n").await?;
    let producer = agent.client("producer").await?;
    let publisher = producer.publisher("Big.frames", "{}").await?;
    // The slow subscriber is a raw socket that is never read after subscribing.
    let mut slow = RawConn::login(agent.flow_tcp, agent.token(), true).await?;
    let reply = slow
        .request(Command::Subscribe {
            chan: ChanRef::Name("Big.frames".into()),
        })
        .await?;
    assert!(reply.is_ok(), "{reply:?}");
    let fast_client = agent.client("fast").await?;
    let fast = fast_client.subscribe("Big.frames").await?;
    until_subscribed(&publisher).await?;
    // 96 MB: far more than the socket buffers between the hub and the slow reader.
    let total = 1500u64;
    let frame = vec![0x5au8; 64 * 1024];
    for n in 1..=total {
        let mut payload = BytesMut::with_capacity(frame.len());
        payload.put_u64_le(n);
        payload.extend_from_slice(&frame[8..]);
        publisher.publish(payload.freeze()).await?;
        // Waiting for the fast subscriber keeps it from ever falling behind itself.
        let got = recv(&fast).await?;
        assert_eq!(got.seq, n, "the fast subscriber missed a message");
        assert_eq!(got.payload[..8], n.to_le_bytes());
    }
    let info = producer.channel("Big.frames").await?;
    assert_eq!(info.stats.msgs, total);
    assert!(
        info.stats.dropped > 0,
        "nothing was dropped: {:?}",
        info.stats
    );
    assert_eq!(fast.dropped(), 0);
    // The slow reader, reading at last, finds a gap (its oldest data was dropped) and the newest message.
    let seqs = until(
        "the newest message on the slow subscriber",
        PATIENCE,
        async {
            let mut seqs = Vec::new();
            while seqs.last() != Some(&total) {
                match slow.next_event(PATIENCE).await? {
                    Some(Event::Data { seq, .. }) => seqs.push(seq),
                    Some(_) => {}
                    None => bail!("the hub closed the slow subscriber"),
                }
            }
            Ok(seqs)
        },
    )
    .await??;
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "out of order");
    assert!(
        seqs.windows(2).any(|w| w[1] > w[0] + 1),
        "no gap: the slow subscriber received everything"
    );
    Ok(())
}

/// A publisher that sends its last messages and leaves at once: a subscriber that has them queued at the hub (here
/// one that had stopped reading) still gets every one of them, and only then hears that the channel is gone.
#[tokio::test]
async fn a_publisher_that_leaves_loses_none_of_what_subscribers_have_queued() -> anyhow::Result<()>
{
    let dir = DataDir::new()?;
    // Queues deep enough that nothing is dropped: only the removal could lose messages.
    let agent = Agent::hub_with_config(
        &dir,
        "[hub]\nsubscriber_queue = 64\nsubscriber_queue_bytes = 67108864\n",
    )
    .await?;
    let producer = agent.client("producer").await?;
    let publisher = producer.publisher("Last.words", "{}").await?;
    let mut sub = RawConn::login(agent.flow_tcp, agent.token(), true).await?;
    let reply = sub
        .request(Command::Subscribe {
            chan: ChanRef::Name("Last.words".into()),
        })
        .await?;
    assert!(reply.is_ok(), "{reply:?}");
    until_subscribed(&publisher).await?;
    // 32 MB while the subscriber does not read: more than the socket buffers between the hub and it can hold, so
    // most of it is still in the hub's queue for that subscriber when the publisher goes.
    let total = 64u64;
    let body = vec![0xa5u8; 512 * 1024];
    for n in 1..=total {
        let mut payload = BytesMut::with_capacity(body.len());
        payload.put_u64_le(n);
        payload.extend_from_slice(&body[8..]);
        publisher.publish(payload.freeze()).await?;
    }
    drop(publisher);
    producer.close_and_wait(PATIENCE).await;
    let mut seqs = Vec::new();
    until("the removal of Last.words", PATIENCE, async {
        loop {
            match sub.next_event(PATIENCE).await? {
                Some(Event::Data { seq, payload, .. }) => {
                    assert_eq!(payload[..8], seq.to_le_bytes(), "message {seq} damaged");
                    seqs.push(seq);
                }
                Some(Event::ChannelRemoved { name, .. }) if name == "Last.words" => return Ok(()),
                Some(_) => {}
                None => bail!(
                    "the hub closed the subscriber after {} messages",
                    seqs.len()
                ),
            }
        }
    })
    .await
    .with_context(|| format!("{} messages before", seqs.len()))??;
    assert_eq!(
        seqs,
        (1..=total).collect::<Vec<_>>(),
        "the subscriber did not get every message before the removal"
    );
    Ok(())
}

// ---------------------------------------------------------------- bad peers

/// `len | op | req | body` with the length computed from the body.
fn frame(op: u8, req: u32, body: &[u8]) -> Vec<u8> {
    let mut v = ((body.len() + 5) as u32).to_le_bytes().to_vec();
    v.push(op);
    v.extend_from_slice(&req.to_le_bytes());
    v.extend_from_slice(body);
    v
}

#[tokio::test]
async fn malformed_frames_close_only_their_own_connection() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let producer = agent.client("producer").await?;
    let publisher = producer.publisher("Steady.stream", "{}").await?;
    let consumer = Client::connect(&agent.ws(), agent.options("consumer")).await?;
    let sub = consumer.subscribe("Steady.stream").await?;
    until_subscribed(&publisher).await?;
    // A steady stream runs the whole time; every message must arrive, in order.
    let streaming = tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_millis(5));
        let mut n = 0u64;
        loop {
            tick.tick().await;
            n += 1;
            if publisher.publish(n.to_le_bytes().to_vec()).await.is_err() {
                return n;
            }
        }
    });
    let (progress_tx, mut progress) = tokio::sync::watch::channel(0u64);
    let consuming: tokio::task::JoinHandle<anyhow::Result<()>> = tokio::spawn(async move {
        let mut last = 0;
        loop {
            let got = recv(&sub).await?;
            if got.seq != last + 1 {
                bail!("the steady stream jumped from {last} to {}", got.seq);
            }
            last = got.seq;
            progress_tx.send_replace(last);
        }
    });

    let corpus: Vec<(&str, bool, Vec<u8>)> = vec![
        ("length below the header", true, vec![3, 0, 0, 0, 1, 2, 3]),
        (
            "length above the maximum",
            true,
            0x7fff_fff0u32.to_le_bytes().to_vec(),
        ),
        ("unknown opcode", true, frame(0x7e, 1, &[])),
        ("unknown opcode before login", false, frame(0x7e, 1, &[])),
        (
            "an event sent as a command",
            true,
            frame(op::DATA, 0, &[0; 18]),
        ),
        ("truncated body", true, frame(op::SUBSCRIBE, 2, &[0, 1])),
        ("trailing bytes", true, frame(op::PING, 3, &[9, 9, 9])),
        (
            "invalid UTF-8 name",
            true,
            frame(
                op::ADD_CHANNEL,
                4,
                &[0, 2, 0, 0xff, 0xfe, 2, 0, 0, 0, b'{', b'}'],
            ),
        ),
        (
            "negative channel id",
            true,
            frame(op::PUBLISH, 0, &[0xff, 0xff, 1, 2, 3]),
        ),
        (
            "bad channel reference tag",
            true,
            frame(op::UNSUBSCRIBE, 5, &[7, 0, 0]),
        ),
        (
            "bad respond status",
            true,
            frame(op::RESPOND, 6, &[0, 0, 0, 0, 0, 0, 0, 0, 9]),
        ),
    ];
    let before = agent.output.matching("killing spurious client").len();
    for (i, (what, login, bytes)) in corpus.iter().enumerate() {
        let mut bad = if *login {
            RawConn::login(agent.flow_tcp, agent.token(), true).await?
        } else {
            RawConn::connect(agent.flow_tcp).await?
        };
        bad.send_bytes(bytes).await?;
        bad.expect_closed(PATIENCE)
            .await
            .with_context(|| format!("case {what:?}"))?;
        agent
            .output
            .wait_for("killing spurious client", before + i + 1, PATIENCE)
            .await
            .with_context(|| format!("case {what:?}"))?;
    }
    // A peer that stops in the middle of a frame is logged too.
    let mut half = RawConn::login(agent.flow_tcp, agent.token(), true).await?;
    half.send_bytes(&frame(op::PING, 1, &[])[..6]).await?;
    half.shutdown_write().await?;
    half.expect_closed(PATIENCE).await?;
    agent
        .output
        .wait_for("in the middle of a frame", 1, PATIENCE)
        .await?;
    let reasons = agent.output.matching("killing spurious client");
    for expected in [
        "shorter than the 5-byte header",
        "exceeds the maximum",
        "unknown opcode 0x7e",
        "trailing bytes",
        "invalid UTF-8",
        "channel id: -1",
    ] {
        assert!(
            reasons.iter().any(|l| l.contains(expected)),
            "no logged reason mentions {expected:?}: {reasons:#?}"
        );
    }

    // Meanwhile the stream went on without a gap, and still goes on.
    let reached = *progress.borrow();
    tokio::time::timeout(PATIENCE, progress.wait_for(|n| *n >= reached + 50))
        .await
        .context("the steady stream stalled")?
        .context("the consumer stopped")?;
    if consuming.is_finished() {
        bail!("the consumer failed: {:?}", consuming.await);
    }
    assert!(producer.is_connected() && consumer.is_connected());
    let fresh = agent.client("fresh").await?;
    assert!(
        fresh
            .channels()
            .await?
            .iter()
            .any(|c| c.name == "Steady.stream")
    );
    streaming.abort();
    consuming.abort();
    Ok(())
}

#[tokio::test]
async fn unauthenticated_peers_are_refused_and_disconnected() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let token = agent.token().to_string();

    // Any command before login: refused, then closed.
    let mut early = RawConn::connect(agent.flow_tcp).await?;
    let req = early.send(Command::ListChannels).await?;
    let closed = early.expect_closed(PATIENCE).await?;
    let refusal = closed.events.iter().find_map(|e| match e {
        Event::Reply {
            req: r,
            result: Err(e),
        } if *r == req => Some(e.code),
        _ => None,
    });
    assert_eq!(
        refusal,
        Some(ErrorCode::NotAuthenticated),
        "{:?}",
        closed.events
    );

    // A wrong token: refused, then closed. The login and a command right behind it
    // go out in one write, so the hub has read both before it closes.
    let wrong_token = "not-the-token-0123456789";
    let mut wrong = RawConn::connect(agent.flow_tcp).await?;
    let mut both = BytesMut::new();
    let req = 1;
    for (req, command) in [
        (
            req,
            Command::Login {
                version: PROTOCOL_VERSION,
                token: wrong_token.into(),
                name: "intruder".into(),
            },
        ),
        (2, Command::ListChannels),
    ] {
        flow::protocol::encode_command(&flow::protocol::Envelope { req, command }, &mut both);
    }
    wrong.send_bytes(&both).await?;
    let closed = wrong.expect_closed(PATIENCE).await?;
    let replies: Vec<_> = closed
        .events
        .iter()
        .filter_map(|e| match e {
            Event::Reply { req, result } => Some((*req, result.clone())),
            _ => None,
        })
        .collect();
    // Exactly one answer: the refusal; the command after it was never executed.
    assert_eq!(replies.len(), 1, "{replies:?}");
    assert_eq!(replies[0].0, req);
    assert_eq!(
        replies[0].1.as_ref().map_err(|e| e.code).err(),
        Some(ErrorCode::AuthFailed)
    );

    // An unsupported protocol version.
    let mut old = RawConn::connect(agent.flow_tcp).await?;
    old.send(Command::Login {
        version: PROTOCOL_VERSION + 1,
        token: token.clone(),
        name: "future".into(),
    })
    .await?;
    let closed = old.expect_closed(PATIENCE).await?;
    assert!(
        closed.events.iter().any(|e| matches!(e, Event::Reply { result: Err(e), .. } if e.code == ErrorCode::VersionMismatch)),
        "{:?}",
        closed.events
    );

    // The SDK reports a wrong token as the hub's refusal, over TCP and WebSocket alike.
    for addr in [agent.tcp(), agent.ws()] {
        let mut opts = agent.options("sdk");
        opts.token = wrong_token.into();
        let err = Client::connect(&addr, opts).await.expect_err("wrong token");
        assert_eq!(err.code(), Some(ErrorCode::AuthFailed), "{addr}: {err}");
    }
    // The admin token is a valid login too.
    let mut opts = agent.options("admin");
    opts.token = dir.admin_token()?;
    let admin = Client::connect(&agent.tcp(), opts).await?;
    assert_eq!(admin.session().map(|s| s.admin), Some(true));

    agent.output.wait_for("wrong token", 3, PATIENCE).await?;
    // Tokens never appear in the log, not even wrong ones.
    let log = agent.output.lines().join("\n");
    assert!(!log.contains(&token), "the token was logged");
    assert!(!log.contains(wrong_token), "a presented token was logged");
    assert!(
        !log.contains(&dir.admin_token()?),
        "the admin token was logged"
    );
    Ok(())
}

// ---------------------------------------------------------------- restarts

#[tokio::test]
async fn the_sdk_restores_channels_and_subscriptions_after_the_server_is_killed()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let (http_addr, tcp_addr) = (agent.http, agent.flow_tcp);
    let mut opts = agent.options("producer");
    opts.reconnect = true;
    let producer = Client::connect(&agent.tcp(), opts).await?;
    let mut opts = agent.options("consumer");
    opts.reconnect = true;
    // The consumer comes over WebSocket: reconnection works on every transport.
    let consumer = Client::connect(&agent.ws(), opts).await?;
    let publisher = producer.publisher("Re.data", r#"{"v":1}"#).await?;
    let _svc = serve_upper(&producer, "Re.upper").await?;
    let sub = consumer.subscribe("Re.data").await?;
    until_subscribed(&publisher).await?;
    publisher.publish(&b"before"[..]).await?;
    assert_eq!(&recv(&sub).await?.payload[..], b"before");

    let mut producer_events = producer.events();
    let mut consumer_events = consumer.events();
    agent.kill9().await?;
    let why = until_event(&mut producer_events, |e| match e {
        ClientEvent::Disconnected(why) => Some(why.clone()),
        _ => None,
    })
    .await
    .context("the producer did not notice the server's death")?;
    assert!(!why.is_empty());
    // Until the channel is re-created it has no id, and nothing is sent.
    assert_eq!(publisher.id(), None);
    assert!(!publisher.has_subscribers());
    let lost = publisher.publish(&b"lost"[..]).await;
    assert!(matches!(lost, Err(FlowError::NotReady(_))), "{lost:?}");

    let agent = Agent::start_with(
        &dir,
        AgentOptions {
            http: Some(http_addr),
            flow_tcp: Some(tcp_addr),
            program: Some("flow-hub"),
            ..AgentOptions::default()
        },
    )
    .await?;
    until_event(&mut consumer_events, |e| {
        matches!(e, ClientEvent::Connected).then_some(())
    })
    .await?;
    // Re-created channel + re-created subscription = the hub tells the producer someone listens.
    until_subscribed(&publisher).await?;
    publisher.publish(&b"after"[..]).await?;
    let got = recv(&sub).await?;
    assert_eq!((&got.payload[..], got.seq), (&b"after"[..], 1));
    // The service came back too, and the header is the one the producer set.
    let other = agent.client("other").await?;
    assert_eq!(
        &other
            .call("Re.upper", &b"back"[..], Duration::from_secs(10))
            .await?[..],
        b"BACK"
    );
    assert_eq!(other.channel("Re.data").await?.header, r#"{"v":1}"#);
    // The killed server's stale Unix socket was replaced by the new one.
    let unix = Client::connect(&agent.unix(), agent.options("unix")).await?;
    unix.ping().await?;
    Ok(())
}

#[tokio::test]
async fn sigterm_says_goodbye_to_clients_and_exits_cleanly() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let mut agent = Agent::hub(&dir).await?;
    let client = agent.client("watcher").await?;
    let mut events = client.events();
    let pid = agent.pid().context("no pid")?;
    let status = std::process::Command::new("kill")
        .args(["-TERM", &pid.to_string()])
        .status()?;
    assert!(status.success());
    let reason = until_event(&mut events, |e| match e {
        ClientEvent::Goodbye(r) => Some(r.clone()),
        _ => None,
    })
    .await?;
    assert!(reason.contains("shutting down"), "{reason}");
    let exit = agent.wait_exit(PATIENCE).await?;
    assert!(exit.success(), "{exit}");
    // The socket file is removed on a clean exit.
    assert!(!agent.flow_unix.exists());
    Ok(())
}

// ---------------------------------------------------------------- example satellites

#[tokio::test]
async fn the_example_publisher_and_subscriber_talk_through_the_hub() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::hub(&dir).await?;
    let addr = agent.tcp().to_string();
    let mut publisher = command("publisher")?;
    publisher
        .args(["--addr", &addr, "--data-dir"])
        .arg(dir.path())
        .args(["--channel", "Example.counter"]);
    let mut publisher = publisher
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()?;
    let mut subscriber = command("subscriber")?;
    subscriber
        .args(["--addr", &addr, "--data-dir"])
        .arg(dir.path())
        .args(["--channel", "Example.counter", "--count", "5"]);
    let out = run(subscriber, b"", PATIENCE).await?.ok()?;
    let lines: Vec<serde_json::Value> = out
        .lines()
        .map(serde_json::from_str)
        .collect::<Result<_, _>>()
        .with_context(|| format!("subscriber output is not JSON lines: {out}"))?;
    assert_eq!(lines.len(), 5, "{out}");
    // The publisher counts from wherever it was when the subscriber arrived; the counts are consecutive.
    let counts: Vec<u64> = lines.iter().filter_map(|l| l["count"].as_u64()).collect();
    assert_eq!(counts.len(), 5, "{out}");
    assert!(counts.windows(2).all(|w| w[1] == w[0] + 1), "{counts:?}");
    publisher.kill().await?;
    Ok(())
}
