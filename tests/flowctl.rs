//! `flowctl` against a running robot-agent: every subcommand, checked from the
//! other side by an SDK satellite, and its errors (one line, non-zero exit).
//!
//! Build the binaries first: `cargo build -p robot-agent -p flowctl`.

use agent_tests::{
    Agent, DataDir, PATIENCE, fixture, recv, run, until, until_subscribed, until_unsubscribed,
};
use anyhow::Context;
use bytes::Bytes;
use flow::{Client, Subscription};

/// A server whose subscriber queues are deep enough that a flat-out `flowctl`
/// publisher is never thinned out by the drop-oldest policy (tested elsewhere).
async fn agent(dir: &DataDir) -> anyhow::Result<Agent> {
    Agent::with_config(dir, "[hub]\nsubscriber_queue = 8192\n").await
}

/// Runs flowctl with `args` and `stdin`.
async fn flowctl(
    agent: &Agent,
    args: &[&str],
    stdin: &[u8],
) -> anyhow::Result<agent_tests::binaries::Finished> {
    let mut cmd = agent.flowctl()?;
    cmd.args(args);
    run(cmd, stdin, PATIENCE).await
}

/// Runs flowctl and returns its stdout, failing unless it succeeded.
async fn ok(agent: &Agent, args: &[&str]) -> anyhow::Result<String> {
    flowctl(agent, args, b"").await?.ok()
}

/// Asserts a failed run printed exactly one line, `flowctl: ...` containing `needle`.
fn assert_one_line_error(out: &agent_tests::binaries::Finished, needle: &str) {
    assert!(!out.success(), "succeeded: {out:?}");
    let lines: Vec<_> = out.stderr.trim_end().lines().collect();
    assert_eq!(lines.len(), 1, "not one line: {:?}", out.stderr);
    assert!(lines[0].starts_with("flowctl: "), "{:?}", lines[0]);
    assert!(
        lines[0].to_lowercase().contains(&needle.to_lowercase()),
        "{:?} does not mention {needle:?}",
        lines[0]
    );
}

#[tokio::test]
async fn channels_lists_every_channel_with_its_properties() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = agent(&dir).await?;
    let sdk = agent.client("sdk").await?;
    let _audio = sdk
        .publisher("Cli.audio", r#"{"mime":"audio/pcm","rate":22050}"#)
        .await?;
    let _svc = sdk.serve("Cli.svc", "{}").await?;
    let _sub = sdk.subscribe("Cli.audio").await?;

    let out = flowctl(&agent, &["channels", "--json"], b"").await?.ok()?;
    let list: serde_json::Value = serde_json::from_str(out.trim())?;
    let find = |name: &str| {
        list.as_array()
            .and_then(|l| l.iter().find(|c| c["name"] == name).cloned())
            .with_context(|| format!("{name} missing from {list}"))
    };
    let audio = find("Cli.audio")?;
    assert_eq!(audio["kind"], "stream");
    assert_eq!(audio["header"]["rate"], 22050);
    assert_eq!(audio["subscribers"], 1);
    assert!(
        audio["owner"]
            .as_str()
            .is_some_and(|o| o.starts_with("sdk#"))
    );
    assert_eq!(
        audio["hash"],
        format!("{:016x}", flow::protocol::channel_hash("Cli.audio"))
    );
    assert_eq!(find("Cli.svc")?["kind"], "service");

    let table = flowctl(&agent, &["channels"], b"").await?.ok()?;
    assert!(
        table.lines().next().is_some_and(|h| h.contains("NAME")),
        "{table}"
    );
    assert!(
        table.contains("Cli.audio") && table.contains("Cli.svc"),
        "{table}"
    );
    Ok(())
}

#[tokio::test]
async fn echo_waits_for_the_channel_and_prints_each_message() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = agent(&dir).await?;
    // echo starts before the channel exists.
    let mut cmd = agent.flowctl()?;
    cmd.args(["echo", "Cli.echo", "--count", "3"]);
    let echo = tokio::spawn(run(cmd, b"", PATIENCE));
    let sdk = agent.client("sdk").await?;
    let publisher = sdk.publisher("Cli.echo", "{}").await?;
    until_subscribed(&publisher).await?;
    publisher.publish(&br#"{"n":1}"#[..]).await?;
    publisher.publish(&b"plain text"[..]).await?;
    publisher.publish(&[0u8, 1, 2, 255][..]).await?;
    let out = echo.await??.ok()?;
    let lines: Vec<_> = out.lines().collect();
    assert_eq!(lines.len(), 3, "{out}");
    assert_eq!(lines[0], r#"{"n":1}"#);
    assert_eq!(lines[1], "plain text");
    assert!(lines[2].starts_with("<4 bytes> seq=3"), "{}", lines[2]);

    // --json: one object per message with its sequence number and size.
    until_unsubscribed(&publisher).await?;
    let mut cmd = agent.flowctl()?;
    cmd.args(["echo", "Cli.echo", "--count", "1", "--json"]);
    let echo = tokio::spawn(run(cmd, b"", PATIENCE));
    // The first subscriber left and a new one arrives: wait for the hub to say so.
    until_subscribed(&publisher).await?;
    publisher.publish(&br#"{"k":"v"}"#[..]).await?;
    let out = echo.await??.ok()?;
    let line: serde_json::Value = serde_json::from_str(out.trim())?;
    assert_eq!(line["seq"], 4);
    assert_eq!(line["bytes"], 9);
    assert_eq!(line["json"]["k"], "v");
    Ok(())
}

/// A subscriber that is in place before flowctl creates the channel.
async fn early_subscriber(agent: &Agent, channel: &str) -> anyhow::Result<(Client, Subscription)> {
    let sdk = agent.client("checker").await?;
    let sub = sdk.subscribe(channel).await?;
    Ok((sdk, sub))
}

#[tokio::test]
async fn pub_sends_stdin_lines_a_file_or_a_directory() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = agent(&dir).await?;

    // stdin: one message per line.
    let (_c1, lines) = early_subscriber(&agent, "Cli.lines").await?;
    flowctl(
        &agent,
        &[
            "pub",
            "Cli.lines",
            "--wait-subscriber",
            "--header",
            r#"{"mime":"text/plain"}"#,
        ],
        b"first line\n{\"x\":1}\nlast\n",
    )
    .await?
    .ok()?;
    for expected in ["first line", "{\"x\":1}", "last"] {
        assert_eq!(recv(&lines).await?.payload, expected.as_bytes());
    }
    assert_eq!(
        lines.info().map(|i| i.header),
        Some(r#"{"mime":"text/plain"}"#.to_string())
    );

    // --file: the whole file as one message.
    let jpeg = fixture("faces/derived/fr_two_people_640x360.jpg")?;
    let (_c2, file) = early_subscriber(&agent, "Cli.file").await?;
    let path = jpeg.to_str().context("path")?;
    flowctl(
        &agent,
        &["pub", "Cli.file", "--wait-subscriber", "--file", path],
        b"",
    )
    .await?
    .ok()?;
    assert_eq!(recv(&file).await?.payload, std::fs::read(&jpeg)?);

    // --dir --rate: every file, in name order, twice with --repeat 2.
    let frames = tempfile::tempdir()?;
    let source = fixture("motion/derived/intel_one-by-one_t2-10s_640x360_15fps/frame_0001.jpg")?;
    let source_dir = source.parent().context("frames dir")?;
    let mut expected = Vec::new();
    for n in [61, 3, 17, 90, 120, 1] {
        let name = format!("frame_{n:04}.jpg");
        std::fs::copy(source_dir.join(&name), frames.path().join(&name))?;
    }
    let mut names: Vec<_> = std::fs::read_dir(frames.path())?
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<_, _>>()?;
    names.sort();
    for name in &names {
        expected.push(Bytes::from(std::fs::read(name)?));
    }
    let (_c3, video) = early_subscriber(&agent, "Cli.video").await?;
    let frames_dir = frames.path().to_str().context("path")?;
    flowctl(
        &agent,
        &[
            "pub",
            "Cli.video",
            "--wait-subscriber",
            "--dir",
            frames_dir,
            "--rate",
            "50",
            "--repeat",
            "2",
        ],
        b"",
    )
    .await?
    .ok()?;
    for round in 0..2 {
        for (i, frame) in expected.iter().enumerate() {
            let got = recv(&video).await?;
            assert_eq!(&got.payload, frame, "round {round} frame {i}");
        }
    }
    Ok(())
}

/// Collects `Agent.audio`-style PCM chunks until `samples` samples have arrived.
async fn collect_pcm(sub: &Subscription, samples: usize) -> anyhow::Result<(Vec<usize>, Vec<i16>)> {
    let mut sizes = Vec::new();
    let mut pcm = Vec::with_capacity(samples);
    until(&format!("{samples} samples"), PATIENCE, async {
        while pcm.len() < samples {
            let chunk = recv(sub)
                .await
                .with_context(|| format!("after {} samples", pcm.len()))?;
            assert_eq!(chunk.payload.len() % 2, 0, "odd chunk size");
            sizes.push(chunk.payload.len());
            pcm.extend(
                chunk
                    .payload
                    .chunks_exact(2)
                    .map(|b| i16::from_le_bytes([b[0], b[1]])),
            );
        }
        anyhow::Ok(())
    })
    .await
    .with_context(|| format!("after {} samples", pcm.len()))??;
    Ok((sizes, pcm))
}

#[tokio::test]
async fn pub_wav_streams_20_ms_chunks_of_22050_hz_pcm() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = agent(&dir).await?;

    // A 22050 Hz recording passes through sample for sample.
    let native = fixture("audio/LJ001-0002.wav")?;
    let reader = hound::WavReader::open(&native)?;
    assert_eq!(reader.spec().sample_rate, 22050);
    let original: Vec<i16> = reader.into_samples::<i16>().collect::<Result<_, _>>()?;
    let (_c1, sub) = early_subscriber(&agent, "Cli.audio").await?;
    flowctl(
        &agent,
        &[
            "pub-wav",
            "Cli.audio",
            native.to_str().context("path")?,
            "--wait-subscriber",
        ],
        b"",
    )
    .await?
    .ok()?;
    let header: serde_json::Value =
        serde_json::from_str(&sub.info().context("no channel info")?.header)?;
    assert_eq!(header["rate"], 22050);
    assert_eq!(header["format"], "s16le");
    let (sizes, pcm) = collect_pcm(&sub, original.len()).await?;
    assert_eq!(pcm, original);
    // 20 ms at 22050 Hz is 441 samples: every chunk but the last is exactly that.
    let (last, full) = sizes.split_last().context("no chunks")?;
    assert!(full.iter().all(|s| *s == 882), "{sizes:?}");
    assert!(*last > 0 && *last <= 882);
    assert_eq!(sizes.len(), original.len().div_ceil(441));

    // A 16 kHz recording is resampled: 22050/16000 as many samples, same chunking.
    let jfk = fixture("audio/jfk.wav")?;
    let reader = hound::WavReader::open(&jfk)?;
    assert_eq!(reader.spec().sample_rate, 16000);
    let input_len = reader.len() as usize;
    // The same arithmetic as the resampler's output length.
    let expected = (input_len as f64 * (22050.0 / 16000.0)).round() as usize;
    let (_c2, sub) = early_subscriber(&agent, "Cli.jfk").await?;
    flowctl(
        &agent,
        &[
            "pub-wav",
            "Cli.jfk",
            jfk.to_str().context("path")?,
            "--wait-subscriber",
            "--chunk-ms",
            "40",
        ],
        b"",
    )
    .await?
    .ok()?;
    let (sizes, pcm) = collect_pcm(&sub, expected).await?;
    assert_eq!(pcm.len(), expected);
    let (_, full) = sizes.split_last().context("no chunks")?;
    assert!(full.iter().all(|s| *s == 1764), "40 ms chunks: {sizes:?}");
    // Speech, not silence: the resampled signal carries energy.
    let peak = pcm.iter().map(|s| s.unsigned_abs()).max().unwrap_or(0);
    assert!(peak > 5000, "peak {peak}");
    // Nothing arrives beyond the expected samples.
    assert!(sub.try_recv().is_none());

    let bad = flowctl(&agent, &["pub-wav", "Cli.x", "/nonexistent.wav"], b"").await?;
    assert_one_line_error(&bad, "/nonexistent.wav");
    Ok(())
}

/// `pub-wav --after CHANNEL` subscribes, says it waits, and streams nothing until a message arrives there: then the
/// whole file follows.
#[tokio::test]
async fn pub_wav_after_a_channel_waits_for_its_next_message() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = agent(&dir).await?;
    let sdk = agent.client("loudspeaker").await?;
    let loudspeaker = sdk.publisher("Cli.speaker", "{}").await?;
    let (_c, sub) = early_subscriber(&agent, "Cli.heard").await?;
    let native = fixture("audio/LJ001-0002.wav")?;
    let samples = hound::WavReader::open(&native)?.len() as usize;
    let mut cmd = agent.flowctl()?;
    cmd.args([
        "pub-wav",
        "Cli.heard",
        native.to_str().context("path")?,
        "--after",
        "Cli.speaker",
    ]);
    let started = agent_tests::start_when_ready(cmd, "waiting for Cli.speaker", PATIENCE).await?;
    // Subscribed and waiting: nothing is streamed however long the loudspeaker stays silent.
    tokio::time::sleep(std::time::Duration::from_millis(500)).await;
    assert!(
        sub.try_recv().is_none(),
        "streamed before the loudspeaker spoke"
    );
    loudspeaker.publish(b"first chunk".to_vec()).await?;
    let (_, pcm) = collect_pcm(&sub, samples).await?;
    assert_eq!(pcm.len(), samples);
    started.await??.ok()?;
    Ok(())
}

#[tokio::test]
async fn call_prints_the_response_or_one_line_of_error() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = agent(&dir).await?;
    let sdk = agent.client("sdk").await?;
    let mut service = sdk.serve("Cli.upper", "{}").await?;
    tokio::spawn(async move {
        while let Some(call) = service.next().await {
            let answer = if call.payload.starts_with(b"{\"fail\"") {
                Err("asked to fail".to_string())
            } else {
                Ok(Bytes::from(call.payload.to_ascii_uppercase()))
            };
            let _ = call.respond(answer).await;
        }
    });
    let out = flowctl(&agent, &["call", "Cli.upper", r#"{"a":"b"}"#], b"")
        .await?
        .ok()?;
    assert_eq!(out.trim(), r#"{"A":"B"}"#);

    let failed = flowctl(&agent, &["call", "Cli.upper", r#"{"fail":1}"#], b"").await?;
    assert_one_line_error(&failed, "asked to fail");
    let missing = flowctl(&agent, &["call", "Cli.none", "{}"], b"").await?;
    assert_one_line_error(&missing, "no channel Cli.none");
    let not_json = flowctl(&agent, &["call", "Cli.upper", "{oops"], b"").await?;
    assert_one_line_error(&not_json, "not valid JSON");
    Ok(())
}

#[tokio::test]
async fn db_set_get_list_del_in_named_databases() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = agent(&dir).await?;
    ok(&agent, &["db", "set", "speed", "0.5"]).await?;
    ok(
        &agent,
        &["db", "set", "pose", r#"{"x":[1,2],"name":"nao"}"#],
    )
    .await?;
    assert_eq!(ok(&agent, &["db", "get", "speed"]).await?.trim(), "0.5");
    let pose: serde_json::Value =
        serde_json::from_str(ok(&agent, &["db", "get", "pose"]).await?.trim())?;
    assert_eq!(pose, serde_json::json!({"x": [1, 2], "name": "nao"}));
    assert_eq!(
        ok(&agent, &["db", "list"])
            .await?
            .lines()
            .collect::<Vec<_>>(),
        vec!["pose", "speed"]
    );

    // Another database has its own variables.
    ok(&agent, &["db", "create", "robot"]).await?;
    ok(&agent, &["db", "--db", "robot", "set", "speed", "2"]).await?;
    assert_eq!(
        ok(&agent, &["db", "--db", "robot", "get", "speed"])
            .await?
            .trim(),
        "2"
    );
    assert_eq!(ok(&agent, &["db", "get", "speed"]).await?.trim(), "0.5");
    assert_eq!(
        ok(&agent, &["db", "dbs"])
            .await?
            .lines()
            .collect::<Vec<_>>(),
        vec!["main", "robot"]
    );

    ok(&agent, &["db", "del", "speed"]).await?;
    assert_eq!(ok(&agent, &["db", "list"]).await?.trim(), "pose");
    let gone = flowctl(&agent, &["db", "get", "speed"], b"").await?;
    assert_one_line_error(&gone, "no variable speed");
    let bad_json = flowctl(&agent, &["db", "set", "k", "{not json"], b"").await?;
    assert_one_line_error(&bad_json, "not valid JSON");
    let no_db = flowctl(&agent, &["db", "--db", "nowhere", "list"], b"").await?;
    assert_one_line_error(&no_db, "no database named nowhere");

    // What flowctl wrote, a satellite reads.
    let sdk = agent.client("sdk").await?;
    assert_eq!(sdk.var_get("pose").await?, Some(pose));
    Ok(())
}

#[tokio::test]
async fn connection_problems_are_one_line_and_a_non_zero_exit() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = agent(&dir).await?;

    let wrong_token = flowctl(&agent, &["--token", "wrong", "channels"], b"").await?;
    assert_one_line_error(&wrong_token, "wrong token");

    // A port nobody listens on any more.
    let closed = std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?;
    let mut cmd = agent.flowctl_at(&format!("tcp://{closed}"))?;
    cmd.arg("channels");
    let refused = run(cmd, b"", PATIENCE).await?;
    assert_one_line_error(&refused, "connection failed");

    let mut cmd = agent.flowctl_at("bogus")?;
    cmd.arg("channels");
    assert_one_line_error(&run(cmd, b"", PATIENCE).await?, "expected tcp://HOST:PORT");

    let mut cmd = agent_tests::command("flowctl")?;
    cmd.env_remove("FLOW_TOKEN").args([
        "--addr",
        &agent.tcp().to_string(),
        "--data-dir",
        "/nonexistent-dir",
        "channels",
    ]);
    assert_one_line_error(&run(cmd, b"", PATIENCE).await?, "no token");

    // The same commands work over the WebSocket and Unix transports.
    for (addr, value) in [
        (agent.ws().to_string(), "\"ws\""),
        (agent.unix().to_string(), "\"unix\""),
    ] {
        let mut cmd = agent.flowctl_at(&addr)?;
        cmd.args(["db", "set", "via", value]);
        run(cmd, b"", PATIENCE).await?.ok()?;
        let out = flowctl(&agent, &["db", "get", "via"], b"").await?.ok()?;
        assert_eq!(out.trim(), value);
    }
    Ok(())
}
