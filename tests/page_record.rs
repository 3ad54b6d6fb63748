//! Recording from the page: with every module on, as `make run` starts them, the holder of a real Chromium page
//! (fake camera and microphone playing the fixtures) presses Record, then Stop. The recorder module writes an MCAP
//! file that the Python `mcap` package opens through its summary (as Foxglove's tooling does), with the camera as
//! `foxglove.CompressedImage` (a real 640x360 JPEG inside), the microphone as `foxglove.RawAudio` and the
//! detections also as `foxglove.ImageAnnotations`, and the page shows what was saved.

use std::path::PathBuf;
use std::time::Duration;

use agent_contract::channels::{AUDIO, DETECTIONS, VIDEO};
use agent_tests::browser_chromium::Chromium;
use agent_tests::browser_media::{jpeg_shape, prepare_pipeline};
use agent_tests::recording::{python_check, read};
use agent_tests::{Agent, DataDir};
use anyhow::Context;
use base64::Engine;

/// Chromium, OpenCV and the TTS share two cores: generous, never a measurement.
const STAGE: Duration = Duration::from_secs(120);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_recorded_from_the_page_opens_with_foxglove_types() -> anyhow::Result<()> {
    let media_dir = tempfile::Builder::new().prefix("record-media-").tempdir()?;
    let media = prepare_pipeline(media_dir.path())?;
    let data = DataDir::new()?;
    let agent = Agent::start(&data).await?;
    let browser = Chromium::launch(&media).await?;
    let tab = browser.open(&agent.page_url("autostart=1&aec=0")).await?;
    browser
        .wait_for(
            &tab,
            "window.agentDebug && agentDebug.role === 'holder' && agentDebug.sent.video > 0 && \
             agentDebug.sent.audio > 0 && agentDebug.detections > 0",
            STAGE,
        )
        .await?;
    browser
        .wait_for(&tab, "!document.getElementById('rec-btn').disabled", STAGE)
        .await?;
    browser
        .eval(&tab, "document.getElementById('rec-btn').click(), true")
        .await?;
    browser
        .wait_for(&tab, "agentDebug.recording.recording === true", STAGE)
        .await?;
    // Two seconds of camera at least, and more detections, go into the file.
    let sent = browser.eval(&tab, "agentDebug.sent.video").await?;
    let detections = browser.eval(&tab, "agentDebug.detections").await?;
    browser
        .wait_for(
            &tab,
            &format!(
                "agentDebug.sent.video > {} && agentDebug.detections > {}",
                sent.as_u64().unwrap_or(0) + 30,
                detections.as_u64().unwrap_or(0) + 5
            ),
            STAGE,
        )
        .await?;
    browser
        .eval(&tab, "document.getElementById('rec-btn').click(), true")
        .await?;
    browser
        .wait_for(
            &tab,
            "agentDebug.recording.recording === false && agentDebug.recording.messages > 0",
            STAGE,
        )
        .await?;
    let state = browser.eval(&tab, "agentDebug.recording").await?;
    let shown = browser
        .eval(&tab, "document.getElementById('rec-state').textContent")
        .await?;
    assert!(
        shown
            .as_str()
            .is_some_and(|s| s.starts_with("saved session-")),
        "{shown}"
    );
    let file = PathBuf::from(state["file"].as_str().context("no file in the state")?);
    assert!(
        file.starts_with(data.path().join("recordings")),
        "{}",
        file.display()
    );
    browser.quit().await;

    // Foxglove's way in: the summary, the schemas, every channel with its header.
    let report = python_check(&file, "indexed").await?;
    println!("{report}");
    let channel = |topic: &str| report["channels"][topic].clone();
    assert_eq!(
        channel(VIDEO.name)["schema"],
        "foxglove.CompressedImage",
        "{report}"
    );
    assert_eq!(
        channel(AUDIO.name)["schema"],
        "foxglove.RawAudio",
        "{report}"
    );
    let annotations = format!("{}/annotations", DETECTIONS.name);
    assert_eq!(
        channel(&annotations)["schema"],
        "foxglove.ImageAnnotations",
        "{report}"
    );
    assert!(
        channel(VIDEO.name)["count"].as_u64() >= Some(30),
        "{report}"
    );
    assert!(
        channel(AUDIO.name)["count"].as_u64() >= Some(50),
        "{report}"
    );
    assert!(
        channel(DETECTIONS.name)["count"].as_u64() >= Some(5),
        "{report}"
    );
    assert_eq!(channel(VIDEO.name)["has_header"], true);
    assert_eq!(
        report["summary"]["message_count"], report["messages"],
        "the summary counts what the file holds"
    );
    assert_eq!(
        state["messages"], report["messages"],
        "the page shows what was written"
    );
    // Each topic read is described in the summary (a channel re-created with a new header gets a second MCAP
    // channel on its topic, so there may be more channels than topics, never fewer).
    let topics = report["channels"].as_object().map_or(0, |c| c.len());
    assert!(
        report["summary"]["channels"].as_u64() >= Some(topics as u64),
        "{report}"
    );
    assert!(
        topics >= 4,
        "camera, microphone, detections and annotations at least: {report}"
    );
    // Foxglove's reading of a camera message: the Python package decodes the page's own JPEG.
    let image = &report["first_image"];
    assert_eq!(image["format"], "jpeg", "{report}");
    assert_eq!(
        (image["width"].as_u64(), image["height"].as_u64()),
        (Some(640), Some(360)),
        "{report}"
    );

    // The Rust reader agrees: a camera message decodes to the page's own JPEG.
    let contents = read(&file)?;
    let frame = contents
        .on(VIDEO.name)
        .first()
        .map(|m| m.data.clone())
        .context("no camera message")?;
    let image: serde_json::Value = serde_json::from_slice(&frame)?;
    assert_eq!(image["format"], "jpeg");
    let jpeg = base64::engine::general_purpose::STANDARD
        .decode(image["data"].as_str().context("no data")?)?;
    let (w, h, _) = jpeg_shape(&jpeg)?;
    assert_eq!((w, h), (640, 360));
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn record_on_the_command_line_records_from_start_to_shutdown() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let file = data.path().join("whole.mcap");
    let opts = agent_tests::AgentOptions {
        config: Some("[modules.vision]\nenabled = false\n".into()),
        args: vec!["--record".into(), file.display().to_string()],
        ..Default::default()
    };
    let agent = Agent::start_with(&data, opts).await?;
    agent
        .output
        .wait_for("recording the session", 1, STAGE)
        .await?;
    let client = agent.client("record-feeder").await?;
    let feed = client
        .publisher("Test.counter", r#"{"format":"json"}"#)
        .await?;
    // The recorder finds the new channel and subscribes: from then on, nothing published is lost.
    agent_tests::until_subscribed(&feed).await?;
    for n in 0..20 {
        feed.publish(format!("{{\"n\":{n}}}").into_bytes()).await?;
    }
    client.ping().await?;
    agent.terminate()?;
    // Logged once the file's summary is written.
    agent.output.wait_for("recording stopped", 1, STAGE).await?;
    let report = python_check(&file, "indexed").await?;
    assert_eq!(report["channels"]["Test.counter"]["count"], 20, "{report}");
    assert_eq!(
        report["channels"]["Test.counter"]["encoding"], "json",
        "{report}"
    );
    Ok(())
}

#[tokio::test]
async fn the_bare_hub_refuses_record_and_says_what_to_use() -> anyhow::Result<()> {
    let data = DataDir::new()?;
    let mut cmd = agent_tests::command("flow-hub")?;
    cmd.arg("--http")
        .arg("127.0.0.1:0")
        .arg("--flow-tcp")
        .arg("127.0.0.1:0")
        .arg("--flow-unix")
        .arg("")
        .arg("--data-dir")
        .arg(data.path())
        .arg("--record")
        .arg(data.path().join("x.mcap"));
    let out = agent_tests::run(cmd, b"", STAGE).await?;
    assert!(!out.status.success());
    assert!(out.stderr.contains("flowctl record"), "{}", out.stderr);
    Ok(())
}
