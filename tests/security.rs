//! The server as an attacker and a careless operator meet it: no panic across abrupt disconnects and shutdown,
//! every route behind the page credential, forged hosts refused, link caps, limits before login, Origin on `/flow`,
//! configuration errors that name file, key and reason, and no token in trace logs.

use std::net::SocketAddr;
use std::time::Duration;

use agent_tests::browser_link::LINK_ONLY_CONFIG;
use agent_tests::http::{Answer, request};
use agent_tests::{Agent, AgentOptions, DataDir, PATIENCE, RawConn};
use anyhow::{Context, bail};
use bytes::BytesMut;
use flow::protocol::{ChanRef, Command, Envelope, PROTOCOL_VERSION, encode_command};
use futures_util::{SinkExt, StreamExt};
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::{Error as WsError, Message};

fn login_frame(token: &str) -> BytesMut {
    let mut buf = BytesMut::new();
    encode_command(
        &Envelope {
            req: 1,
            command: Command::Login {
                version: PROTOCOL_VERSION,
                token: token.into(),
                name: "churn".into(),
            },
        },
        &mut buf,
    );
    buf
}

/// Drops a socket with a reset instead of a FIN, as a killed process or a broken network does.
fn reset(stream: TcpStream) {
    let _ = stream.set_zero_linger();
}

/// Lines of the server's output that show a panic.
fn panics(agent: &Agent) -> Vec<String> {
    agent.output.matching("panicked")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_panic_across_a_churn_of_abrupt_disconnects_and_a_sigterm_under_load()
-> anyhow::Result<()> {
    let data = DataDir::new()?;
    // Every module on, as `make run` starts it: their in-process links see the shutdown too.
    let mut agent = Agent::start(&data).await?;
    agent.output.wait_for("module started", 5, PATIENCE).await?;

    // Load: 50 Hz into two subscribers, one of which reads slowly.
    let producer = agent.client("load-pub").await?;
    let publisher = producer.publisher("Load.stream", "{}").await?;
    let fast = agent.client("load-fast").await?;
    let fast_sub = fast.subscribe("Load.stream").await?;
    let slow = agent.client("load-slow").await?;
    let slow_sub = slow.subscribe("Load.stream").await?;
    let load = tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_millis(20));
        loop {
            tick.tick().await;
            if publisher.publish(vec![7u8; 882]).await.is_err() {
                return;
            }
        }
    });
    let readers = tokio::spawn(async move {
        loop {
            tokio::select! {
                m = fast_sub.recv() => if m.is_none() { return },
                m = slow_sub.recv() => {
                    if m.is_none() { return }
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            }
        }
    });

    let addr = agent.flow_tcp;
    let token = agent.token().to_string();
    for i in 0..220 {
        let mut stream = TcpStream::connect(addr).await?;
        match i % 5 {
            // Logged in, subscribed, then reset.
            0 => {
                let mut conn = RawConn::login(addr, &token, true).await?;
                conn.send(Command::Subscribe {
                    chan: ChanRef::Name("Load.stream".into()),
                })
                .await?;
                drop(conn);
                stream.write_all(&login_frame(&token)).await?;
                reset(stream);
            }
            // Logged in, then a clean close.
            1 => {
                stream.write_all(&login_frame(&token)).await?;
                stream.shutdown().await?;
            }
            // Half a frame, then reset.
            2 => {
                let frame = login_frame(&token);
                stream.write_all(&frame[..frame.len() / 2]).await?;
                reset(stream);
            }
            // Reset before saying anything.
            3 => reset(stream),
            // A logged-in SDK client that subscribes and goes away at once.
            _ => {
                drop(stream);
                let c = agent.client("churn-sdk").await?;
                let _sub = c.subscribe("Load.stream").await?;
                drop(c);
            }
        }
    }
    // Processes killed with SIGKILL while subscribed.
    for _ in 0..4 {
        let mut cmd = agent.flowctl()?;
        cmd.arg("echo").arg("Load.stream");
        cmd.stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null());
        let mut child = cmd.spawn()?;
        tokio::time::sleep(Duration::from_millis(300)).await;
        child.kill().await?;
    }
    agent
        .output
        .wait_for("connection closed", 150, PATIENCE)
        .await?;
    assert_eq!(
        panics(&agent),
        Vec::<String>::new(),
        "panics during the churn"
    );

    // SIGTERM while the load still runs.
    agent.terminate()?;
    let status = agent.wait_exit(PATIENCE).await?;
    load.abort();
    readers.abort();
    assert!(status.success(), "exit status {status:?}");
    assert_eq!(panics(&agent), Vec::<String>::new(), "panics at shutdown");
    let spurious: Vec<String> = agent
        .output
        .matching("killing spurious client")
        .into_iter()
        .filter(|l| l.contains("shutting down") || l.contains("write failed"))
        .collect();
    assert!(
        spurious.is_empty(),
        "a normal shutdown is not a spurious client: {spurious:?}"
    );
    Ok(())
}

/// The three credentials a route is tried with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Cred {
    None,
    Wrong,
    Right,
}

/// A session cookie, got the way the page gets it: `/?token=` -> 303 with `Set-Cookie`.
async fn sign_in(agent: &Agent, query: &str) -> anyhow::Result<(String, Answer)> {
    let path = format!("/?token={}{query}", agent.page_token());
    let answer = request(agent.http, "GET", &path, &[]).await?;
    anyhow::ensure!(
        answer.status == 303,
        "sign-in gave {}: {}",
        answer.status,
        answer.body
    );
    let set = answer.header("set-cookie").context("no Set-Cookie")?;
    let cookie = set.split(';').next().context("empty cookie")?.to_string();
    Ok((cookie, answer.clone()))
}

/// A WebSocket upgrade with `headers`; the status of the answer (101 when accepted).
async fn ws_status(url: &str, headers: &[(&'static str, &str)]) -> anyhow::Result<u16> {
    let mut req = url.into_client_request()?;
    for (n, v) in headers {
        req.headers_mut().insert(*n, v.parse()?);
    }
    match tokio_tungstenite::connect_async(req).await {
        Ok((mut ws, res)) => {
            let _ = ws.close(None).await;
            Ok(res.status().as_u16())
        }
        Err(WsError::Http(res)) => Ok(res.status().as_u16()),
        Err(e) => bail!("{url}: {e}"),
    }
}

async fn fresh_session(agent: &Agent, cookie: &str) -> anyhow::Result<String> {
    let own = format!("http://{}", agent.http);
    let a = request(
        agent.http,
        "POST",
        "/api/session",
        &[("Cookie", cookie), ("Origin", &own)],
    )
    .await?;
    anyhow::ensure!(a.status == 200, "session: {} {}", a.status, a.body);
    let v: serde_json::Value = serde_json::from_str(a.body.trim())?;
    Ok(v["session"].as_str().context("no session")?.to_string())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_route_refuses_requests_without_the_page_credential() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let agent = agent_tests::browser_link::start_link_only(&data).await?;
    agent.output.wait_for("module started", 3, PATIENCE).await?;
    let (cookie, signed) = sign_in(&agent, "&autostart=1").await?;
    let set = signed.header("set-cookie").unwrap_or_default();
    assert!(
        set.contains("HttpOnly") && set.contains("SameSite=Strict"),
        "{set}"
    );
    assert_eq!(
        signed.header("location"),
        Some("/?autostart=1"),
        "the token leaves the address"
    );
    let wrong = request(agent.http, "GET", "/?token=not-the-token", &[]).await?;
    assert_eq!(wrong.status, 401);
    assert!(
        wrong.body.contains("page.token"),
        "the sign-in page says how: {}",
        wrong.body
    );

    let own = format!("http://{}", agent.http);
    let port = agent.http.port();
    let wrong_cookie = format!(
        "robot_agent_{port}=1700000000.0011223344556677.{}",
        "ab".repeat(32)
    );
    let right_bearer = format!("Bearer {}", agent.page_token());
    let routes: [(&str, &str, u16); 5] = [
        ("GET", "/", 200),
        ("GET", "/js/main.js", 200),
        ("POST", "/api/session", 200),
        ("GET", "/api/channels", 200),
        ("GET", "/api/status", 200),
    ];
    let mut table = Vec::new();
    for (method, path, ok) in routes {
        for cred in [Cred::None, Cred::Wrong, Cred::Right] {
            let mut headers: Vec<(&str, &str)> = vec![("Origin", &own)];
            match cred {
                Cred::None => {}
                Cred::Wrong => headers.push(("Cookie", &wrong_cookie)),
                Cred::Right => headers.push(("Cookie", &cookie)),
            }
            let a = request(agent.http, method, path, &headers).await?;
            let expected = if cred == Cred::Right { ok } else { 401 };
            table.push(format!("{method} {path} {cred:?}: {}", a.status));
            assert_eq!(
                a.status, expected,
                "{method} {path} with {cred:?}: {}",
                a.body
            );
        }
        // Tools present a token instead of the cookie.
        let a = request(
            agent.http,
            method,
            path,
            &[("Origin", &own), ("Authorization", &right_bearer)],
        )
        .await?;
        assert_eq!(a.status, ok, "{method} {path} with a bearer token");
        let a = request(
            agent.http,
            method,
            path,
            &[("Origin", &own), ("Authorization", "Bearer nope")],
        )
        .await?;
        assert_eq!(a.status, 401, "{method} {path} with a wrong bearer token");
    }
    // The API answers 401 in JSON, the page with the sign-in page.
    let api = request(agent.http, "GET", "/api/status", &[]).await?;
    assert!(api.body.contains("\"error\""), "{}", api.body);
    let page = request(agent.http, "GET", "/", &[]).await?;
    assert!(page.body.contains("Sign in"), "{}", page.body);
    // Health stays open (probes have no credential).
    assert_eq!(
        request(agent.http, "GET", "/healthz", &[]).await?.status,
        200
    );

    // The page link: a session token alone is not enough.
    let session = fresh_session(&agent, &cookie).await?;
    let url = format!("ws://{}/link?session={session}", agent.http);
    assert_eq!(
        ws_status(&url, &[("Origin", &own)]).await?,
        401,
        "link without a credential"
    );
    assert_eq!(
        ws_status(&url, &[("Origin", &own), ("Cookie", &wrong_cookie)]).await?,
        401,
        "link with a wrong cookie"
    );
    assert_eq!(
        ws_status(&url, &[("Origin", &own), ("Cookie", &cookie)]).await?,
        101,
        "link with the cookie"
    );
    println!("route table:\n{}", table.join("\n"));
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn forged_hosts_are_refused_even_with_the_credential() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let agent = agent_tests::browser_link::start_link_only(&data).await?;
    let bearer = format!("Bearer {}", agent.page_token());
    let port = agent.http.port();
    for (host, expected) in [
        (format!("evil.example:{port}"), 403),
        (format!("10.66.66.66:{port}"), 403),
        (format!("localhost:{port}"), 200),
        (format!("127.0.0.1:{port}"), 200),
    ] {
        let a = request(
            agent.http,
            "GET",
            "/api/channels",
            &[("Host", &host), ("Authorization", &bearer)],
        )
        .await?;
        assert_eq!(a.status, expected, "Host {host}: {}", a.body);
    }
    // A DNS-rebinding page cannot even reach the sign-in exchange under its own name.
    let path = format!("/?token={}", agent.page_token());
    let a = request(agent.http, "GET", &path, &[("Host", "evil.example")]).await?;
    assert_eq!(a.status, 403);
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn page_links_are_capped_per_credential_and_in_total() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let config =
        format!("{LINK_ONLY_CONFIG}[modules.browser]\nmax_links = 3\nmax_links_per_session = 2\n");
    let agent = Agent::with_config(&data, &config).await?;
    agent.output.wait_for("module started", 3, PATIENCE).await?;
    let own = format!("http://{}", agent.http);
    let open = |cookie: String, session: String| {
        let url = format!("ws://{}/link?session={session}", agent.http);
        let own = own.clone();
        async move {
            let mut req = url.into_client_request()?;
            req.headers_mut().insert("Origin", own.parse()?);
            req.headers_mut().insert("Cookie", cookie.parse()?);
            Ok::<_, anyhow::Error>(tokio_tungstenite::connect_async(req).await)
        }
    };
    let (a, _) = sign_in(&agent, "").await?;
    let (b, _) = sign_in(&agent, "").await?;
    let (c, _) = sign_in(&agent, "").await?;
    let spare_a = fresh_session(&agent, &a).await?;
    let a1 = open(a.clone(), fresh_session(&agent, &a).await?).await??;
    let a2 = open(a.clone(), fresh_session(&agent, &a).await?).await??;
    // A third page under the same cookie: refused where the page can read why, and at the socket.
    let refused = request(
        agent.http,
        "POST",
        "/api/session",
        &[("Cookie", &a), ("Origin", &own)],
    )
    .await?;
    assert_eq!(refused.status, 429, "{}", refused.body);
    assert!(
        refused.body.contains("max_links_per_session"),
        "{}",
        refused.body
    );
    match open(a.clone(), spare_a.clone()).await? {
        Err(WsError::Http(res)) => assert_eq!(res.status().as_u16(), 429),
        other => bail!("a third link under one cookie was not refused: {other:?}"),
    }
    // Another browser may still open one; then the total is reached.
    let b1 = open(b.clone(), fresh_session(&agent, &b).await?).await??;
    let refused = request(
        agent.http,
        "POST",
        "/api/session",
        &[("Cookie", &c), ("Origin", &own)],
    )
    .await?;
    assert_eq!(refused.status, 429);
    assert!(refused.body.contains("max_links"), "{}", refused.body);
    agent.output.wait_for("link refused", 1, PATIENCE).await?;
    // A page that leaves frees its place.
    drop(a1);
    let mut last = None;
    for _ in 0..50 {
        let r = request(
            agent.http,
            "POST",
            "/api/session",
            &[("Cookie", &c), ("Origin", &own)],
        )
        .await?;
        if r.status == 200 {
            last = Some(r);
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(last.is_some(), "the freed place was not given back");
    drop((a2, b1));
    Ok(())
}

/// Sends the first bytes of a frame that claims `len` bytes, as an attacker that never finishes it.
async fn partial_frame(addr: SocketAddr, len: u32) -> anyhow::Result<TcpStream> {
    let mut s = TcpStream::connect(addr).await?;
    let mut head = len.to_le_bytes().to_vec();
    head.extend_from_slice(&[0x01; 60]);
    s.write_all(&head).await?;
    Ok(s)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn strangers_get_a_small_frame_a_login_deadline_and_a_cap() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let config =
        format!("{LINK_ONLY_CONFIG}[hub]\nlogin_timeout_ms = 1500\nmax_unauthenticated = 6\n");
    let agent = Agent::with_config(&data, &config).await?;

    // A frame larger than a login is refused before the hub reserves memory for it.
    let mut big = RawConn::connect(agent.flow_tcp).await?;
    big.send_bytes(&(16u32 << 20).to_le_bytes()).await?;
    big.expect_closed(PATIENCE).await?;
    agent
        .output
        .wait_for("killing spurious client", 1, PATIENCE)
        .await?;
    assert!(
        agent
            .output
            .matching("killing spurious client")
            .iter()
            .any(|l| l.contains("16384")),
        "the reason names the pre-login limit: {:?}",
        agent.output.matching("killing spurious client")
    );

    // A connection that never logs in is closed at the deadline, with a reason.
    let mut idle = RawConn::connect(agent.flow_tcp).await?;
    idle.expect_closed(PATIENCE).await?;
    agent
        .output
        .wait_for("no login within 1500 ms", 1, PATIENCE)
        .await?;

    // At most six wait to log in; a seventh gets in and the oldest waiting one is closed to make room.
    let mut waiting = Vec::new();
    for _ in 0..6 {
        waiting.push(RawConn::connect(agent.flow_tcp).await?);
    }
    // The six are registered once the hub has seen them.
    tokio::time::sleep(Duration::from_millis(200)).await;
    let _seventh = RawConn::connect(agent.flow_tcp).await?;
    waiting[0].expect_closed(Duration::from_secs(1)).await?;
    agent
        .output
        .wait_for("hub.max_unauthenticated", 1, PATIENCE)
        .await?;
    // A real client still logs in while the table is full.
    agent.client("amid-strangers").await?;
    drop(waiting);
    // Once they are gone, a real client logs in as usual.
    let mut ok = None;
    for _ in 0..50 {
        if let Ok(c) = agent.client("after-strangers").await {
            ok = Some(c);
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(
        ok.is_some(),
        "a real client could not log in after the strangers left"
    );
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fifty_hostile_connections_leave_memory_near_idle() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let agent = agent_tests::browser_link::start_link_only(&data).await?;
    agent.output.wait_for("module started", 3, PATIENCE).await?;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let idle_kb = agent.rss_kb()?;

    // 25 TCP connections announcing 16 MiB frames and 25 `/flow` WebSockets sending 16 MiB messages.
    let mut tcp = Vec::new();
    for _ in 0..25 {
        tcp.push(partial_frame(agent.flow_tcp, 16 << 20).await?);
    }
    let url = format!("ws://{}/flow", agent.http);
    let mut sockets = tokio::task::JoinSet::new();
    for _ in 0..25 {
        let url = url.clone();
        sockets.spawn(async move {
            let Ok((mut ws, _)) = tokio_tungstenite::connect_async(url.as_str()).await else {
                return;
            };
            let _ = ws
                .send(Message::Binary(vec![0x01u8; 16 << 20].into()))
                .await;
            tokio::time::sleep(Duration::from_secs(3)).await;
        });
    }
    let mut peak_kb = idle_kb;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(4);
    while tokio::time::Instant::now() < deadline {
        peak_kb = peak_kb.max(agent.rss_kb()?);
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    tokio::time::timeout(PATIENCE, async {
        while sockets.join_next().await.is_some() {}
    })
    .await
    .context("the hostile WebSockets did not finish")?;
    drop(tcp);
    let grew_mb = (peak_kb.saturating_sub(idle_kb)) as f64 / 1024.0;
    println!(
        "RSS idle {:.1} MB, peak under 50 hostile connections {:.1} MB (+{grew_mb:.1} MB)",
        idle_kb as f64 / 1024.0,
        peak_kb as f64 / 1024.0
    );
    assert!(
        grew_mb <= 20.0,
        "RSS grew {grew_mb:.1} MB under 50 hostile connections"
    );
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_flow_websocket_refuses_foreign_origins_and_serves_tools() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let agent = agent_tests::browser_link::start_link_only(&data).await?;
    let url = format!("ws://{}/flow", agent.http);
    let own = format!("http://{}", agent.http);
    assert_eq!(
        ws_status(&url, &[("Origin", "http://evil.example")]).await?,
        403
    );
    assert_eq!(ws_status(&url, &[("Origin", &own)]).await?, 101);
    assert_eq!(ws_status(&url, &[]).await?, 101, "tools send no Origin");
    // A real satellite over `/flow` logs in and moves a frame larger than one WebSocket message.
    let a = flow::Client::connect(&agent.ws(), agent.options("ws-pub")).await?;
    let b = agent.client("tcp-sub").await?;
    let sub = b.subscribe("Big.frames").await?;
    let publisher = a.publisher("Big.frames", "{}").await?;
    agent_tests::until_subscribed(&publisher).await?;
    let payload: Vec<u8> = (0..1_000_000u32).map(|i| (i % 251) as u8).collect();
    publisher.publish(payload.clone()).await?;
    let got = agent_tests::recv(&sub).await?;
    assert_eq!(got.payload.as_ref(), payload.as_slice());
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn configuration_errors_name_the_file_the_key_and_the_reason() -> anyhow::Result<()> {
    for (toml, expected) in [
        (
            "[modules.bogus]\nenabled = false\n",
            "test-config.toml: modules.bogus: no such module",
        ),
        (
            "[modules.video_y]\nquality = 500\n",
            "test-config.toml: modules.video_y.quality: invalid value: integer `500`",
        ),
        (
            "[modules.tts]\nchunk_ms = 1\n",
            "test-config.toml: modules.tts.chunk_ms: 1 is outside 10..=500",
        ),
        (
            "[server]\nhttp = \"0.0.0.0:0\"\n[http]\nopen_on_loopback = true\n",
            "test-config.toml: http.open_on_loopback: ",
        ),
        (
            "[agent]\nlanguage = \"fr\"\n",
            "test-config.toml: agent.language: unknown language \"fr\" (expected \"en\" or \"it\")",
        ),
    ] {
        let data = DataDir::new()?;
        let err = Agent::with_config(&data, toml)
            .await
            .expect_err(toml)
            .to_string();
        assert!(err.contains("invalid configuration"), "{toml}: {err}");
        assert!(
            err.contains(expected),
            "{toml}: expected {expected:?} in:\n{err}"
        );
    }
    // Files the server cannot use are named by their path.
    for (blocked, expected) in [("token", "/token: "), ("pairs.redb", "pairs.redb: ")] {
        let data = DataDir::new()?;
        std::fs::create_dir(data.path().join(blocked))?;
        let err = Agent::start(&data).await.expect_err(blocked).to_string();
        let shown = format!("{}{expected}", data.path().display());
        assert!(
            err.contains(&shown) || err.contains(expected),
            "{blocked}: expected the path in:\n{err}"
        );
        assert!(
            err.contains(&data.path().display().to_string()),
            "{blocked}: no path in:\n{err}"
        );
    }
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_oversized_page_message_closes_with_1009_and_a_logged_reason() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let agent = agent_tests::browser_link::start_link_only(&data).await?;
    agent.output.wait_for("module started", 3, PATIENCE).await?;
    let (cookie, _) = sign_in(&agent, "").await?;
    let session = fresh_session(&agent, &cookie).await?;
    let mut req = format!("ws://{}/link?session={session}", agent.http).into_client_request()?;
    req.headers_mut()
        .insert("Origin", format!("http://{}", agent.http).parse()?);
    req.headers_mut().insert("Cookie", cookie.parse()?);
    let (mut ws, _) = tokio_tungstenite::connect_async(req).await?;
    let mut big = vec![0x02u8, 0, 0, 0, 0, 0, 0, 0];
    big.extend(std::iter::repeat_n(0xffu8, 2 << 20));
    ws.send(Message::Binary(big.into())).await?;
    let deadline = tokio::time::Instant::now() + PATIENCE;
    loop {
        match tokio::time::timeout_at(deadline, ws.next())
            .await
            .context("no close")?
        {
            Some(Ok(Message::Close(Some(frame)))) => {
                assert_eq!(u16::from(frame.code), 1009, "{frame:?}");
                break;
            }
            Some(Ok(_)) => continue,
            other => bail!("expected a close frame with 1009, got {other:?}"),
        }
    }
    agent.output.wait_for("1009", 1, PATIENCE).await?;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn trace_logs_never_show_a_login_token() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let agent = Agent::start_with(
        &data,
        AgentOptions {
            config: Some(LINK_ONLY_CONFIG.into()),
            log: Some("trace".into()),
            ..AgentOptions::default()
        },
    )
    .await?;
    let over_ws = flow::Client::connect(&agent.ws(), agent.options("ws-sat")).await?;
    let over_tcp = agent.client("tcp-sat").await?;
    over_ws.publisher("Trace.check", "{}").await?;
    agent
        .output
        .wait_for("tcp-sat logged in", 1, PATIENCE)
        .await?;
    agent
        .output
        .wait_for("ws-sat logged in", 1, PATIENCE)
        .await?;
    let page_token = agent.page_token().to_string();
    let leaks: Vec<String> = agent
        .output
        .lines()
        .into_iter()
        .filter(|l| {
            l.contains(agent.token()) || l.contains(&data.admin_token().unwrap_or_default())
        })
        .collect();
    assert!(leaks.is_empty(), "a token in the log: {leaks:?}");
    // The page token appears once: in the address printed for the operator.
    assert_eq!(
        agent.output.matching(&page_token).len(),
        1,
        "{:?}",
        agent.output.matching(&page_token)
    );
    drop((over_ws, over_tcp));
    Ok(())
}
