//! The whole agent as `make run` starts it, in a real browser: every module on (the embedded default configuration),
//! a real `whisper-sat`, headless Chromium with a fake camera (a portrait on the right of the frame, then a QR code)
//! and a fake microphone asking questions in another engine's voice. What the page shows is read from the page
//! itself: its debug hook and the pixels of the overlay canvas.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent_contract::channels::{RULES, TRANSCRIPT};
use agent_tests::browser_chromium::{Chromium, Tab};
use agent_tests::browser_media::prepare_pipeline;
use agent_tests::{Agent, DataDir, Satellite};
use anyhow::{Context, bail};
use serde_json::Value;

/// Generous bound for each stage: on two cores the browser, the detectors and Whisper share the machine.
const STAGE: Duration = Duration::from_secs(90);

/// Every JSON message of a subscription, collected in the background.
fn collect(sub: flow::Subscription) -> Arc<Mutex<Vec<Value>>> {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let out = seen.clone();
    tokio::spawn(async move {
        while let Some(d) = sub.recv().await {
            if let Ok(v) = serde_json::from_slice::<Value>(&d.payload) {
                out.lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .push(v);
            }
        }
    });
    seen
}

/// Waits until a rule whose path ends with `rule` has fired.
async fn fired(traces: &Arc<Mutex<Vec<Value>>>, rule: &str) -> anyhow::Result<()> {
    let deadline = tokio::time::Instant::now() + STAGE;
    loop {
        let found = traces
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
            .any(|t| t["rule"].as_str().is_some_and(|r| r.ends_with(rule)));
        if found {
            return Ok(());
        }
        if tokio::time::Instant::now() > deadline {
            let all = traces
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .clone();
            bail!("rule {rule} never fired; traces: {all:?}");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Intersection over union of a face box (`{x, y, w, h}`) and `[x, y, w, h]`.
fn iou(face: &Value, b: [f64; 4]) -> f64 {
    let a = ["x", "y", "w", "h"].map(|k| face[k].as_f64().unwrap_or(0.0));
    let ix = (a[0] + a[2]).min(b[0] + b[2]) - a[0].max(b[0]);
    let iy = (a[1] + a[3]).min(b[1] + b[3]) - a[1].max(b[1]);
    let inter = ix.max(0.0) * iy.max(0.0);
    inter / (a[2] * a[3] + b[2] * b[3] - inter)
}

/// The lit pixels of the overlay canvas, in its left and right halves.
async fn overlay_pixels(browser: &Chromium, tab: &Tab) -> anyhow::Result<(u64, u64)> {
    let v = browser
        .eval(
            tab,
            "(() => { const c = document.getElementById('overlay'); const ctx = c.getContext('2d');
              const d = ctx.getImageData(0, 0, c.width, c.height).data; let l = 0, r = 0;
              for (let i = 3; i < d.length; i += 4) { if (d[i] > 0) { ((i >> 2) % c.width < c.width / 2) ? l++ : r++; } }
              return [l, r]; })()",
        )
        .await?;
    Ok((
        v[0].as_u64().context("left count")?,
        v[1].as_u64().context("right count")?,
    ))
}

/// How many speech chunks the page has played and which visemes the mouth has shown since `watch_visemes`.
async fn visemes_seen(browser: &Chromium, tab: &Tab) -> anyhow::Result<usize> {
    let v = browser.eval(tab, "window.__visemes.size").await?;
    v.as_u64()
        .map(|n| n as usize)
        .context("no viseme watcher in the page")
}

async fn watch_visemes(browser: &Chromium, tab: &Tab) -> anyhow::Result<()> {
    browser
        .eval(
            tab,
            "window.__visemes = new Set(); setInterval(() => { if (agentDebug.viseme && agentDebug.viseme !== 'sil') __visemes.add(agentDebug.viseme); }, 15); true",
        )
        .await?;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_every_module_on_the_page_draws_what_the_agent_sees_and_plays_what_it_says()
-> anyhow::Result<()> {
    let media_dir = tempfile::Builder::new()
        .prefix("pipeline-media-")
        .tempdir()?;
    let media = prepare_pipeline(media_dir.path())?;
    let data = DataDir::new()?;
    // No configuration: the embedded defaults, every module on, as `make run` starts it.
    let agent = Agent::start(&data).await?;
    agent
        .output
        .wait_for("module started", 6, agent_tests::PATIENCE)
        .await?;
    let _ears = Satellite::start(&agent, "pipeline-ears").await?;
    let hub = agent.client("pipeline-watch").await?;
    let rules = collect(hub.subscribe(RULES.name).await?);
    let transcripts = collect(hub.subscribe(TRANSCRIPT.name).await?);
    let seen = collect(
        hub.subscribe(agent_contract::channels::DETECTIONS.name)
            .await?,
    );

    let browser = Chromium::launch(&media).await?;
    let tab = browser.open(&agent.page_url("autostart=1&aec=0")).await?;
    browser
        .wait_for(
            &tab,
            "window.agentDebug && agentDebug.role === 'holder' && agentDebug.sent.video > 0 && agentDebug.sent.audio > 0",
            STAGE,
        )
        .await?;
    watch_visemes(&browser, &tab).await?;

    // The vision module's faces are drawn over the preview: a box item, and lit pixels on the canvas. The portrait
    // is on the right of the camera image; the preview is a mirror, so its box is on the canvas's left.
    browser
        .wait_for(
            &tab,
            "agentDebug.overlayItems > 0 && agentDebug.detections > 5",
            STAGE,
        )
        .await?;
    // The real face, not a ghost: fixtures/ground_truth.json has fr_obama.jpg's face at left 349, top 142, right
    // 617, bottom 409; scaled by 330/1137 and placed at (356, 15) in the frame that is (457, 56) to (535, 134).
    let truth = [457.0, 56.0, 78.0, 78.0];
    let deadline = tokio::time::Instant::now() + STAGE;
    let found = loop {
        let hit = seen
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
            .flat_map(|d| d["faces"].as_array().cloned().unwrap_or_default())
            .find(|f| iou(f, truth) >= 0.3);
        if let Some(hit) = hit {
            break hit;
        }
        if tokio::time::Instant::now() > deadline {
            bail!("the vision module never found the portrait's face");
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    println!("face found at {found}");
    let mut drawn = (0, 0);
    for _ in 0..100 {
        drawn = overlay_pixels(&browser, &tab).await?;
        if drawn.0 > 200 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert!(
        drawn.0 > 200 && drawn.0 > drawn.1,
        "the face box should be drawn on the mirrored preview's left: lit pixels (left, right) = {drawn:?}"
    );
    // The status strip's "camera -> box": measured on the page's clock from the frame's capture to its boxes.
    browser
        .wait_for(&tab, "agentDebug.latency.camera.last > 0", STAGE)
        .await?;
    let camera = browser.eval(&tab, "agentDebug.latency").await?;
    println!("page latencies after the face: {camera}");
    assert!(
        camera["camera"]["median"]
            .as_f64()
            .is_some_and(|ms| ms > 0.0 && ms < 10_000.0),
        "{camera}"
    );
    let png = browser.screenshot(&tab).await?;
    std::fs::create_dir_all(agent_tests::artifacts_dir())?;
    std::fs::write(agent_tests::artifacts_dir().join("pipeline-face.png"), &png)?;

    // The avatar looks towards the person: a face on the right of the camera image is the avatar's left, so its
    // eyes and head turn to the viewer's left.
    browser
        .wait_for(
            &tab,
            "agentDebug.eyeOffset.x < -0.2 && agentDebug.head.yaw < -0.05",
            STAGE,
        )
        .await?;

    // The greeting: the brain's rule fires, its speech plays in the page and the mouth moves.
    fired(&rules, "greet").await?;
    browser
        .wait_for(&tab, "agentDebug.speechChunks > 10", STAGE)
        .await?;
    browser
        .wait_for(&tab, "window.__visemes.size >= 3", STAGE)
        .await?;

    // A spoken question is transcribed by the real whisper-sat and answered aloud.
    fired(&rules, "answer.time").await?;
    let heard: Vec<String> = transcripts
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .iter()
        .filter_map(|t| t["text"].as_str().map(str::to_owned))
        .collect();
    assert!(
        heard.iter().any(|t| t.to_lowercase().contains("time")),
        "transcripts: {heard:?}"
    );
    // The turn's "speech end -> reply" reached the status strip from the observer module.
    browser
        .wait_for(&tab, "agentDebug.latency.voice.last > 0", STAGE)
        .await?;
    let voice = browser.eval(&tab, "agentDebug.latency.voice.last").await?;
    println!("speech end -> reply audio: {voice} ms");
    // Beside it, the strip names the voice that answers: English speaks with Piper by default (the welcome's voice).
    browser
        .wait_for(
            &tab,
            "agentDebug.latency.engine === 'piper' && document.getElementById('st-voice').textContent.includes('Piper')",
            STAGE,
        )
        .await?;
    let before = browser.eval(&tab, "agentDebug.speechChunks").await?;
    let before = before.as_u64().unwrap_or_default();
    browser
        .wait_for(
            &tab,
            &format!("agentDebug.speechChunks > {}", before + 10),
            STAGE,
        )
        .await?;

    // Then the camera shows a QR code: its polygon is drawn, and asked to, the agent reads it aloud.
    browser
        .wait_for(
            &tab,
            "agentDebug.overlayItems > 0 && document.getElementById('overlay') !== null",
            STAGE,
        )
        .await?;
    fired(&rules, "answer.read").await?;
    let shown = visemes_seen(&browser, &tab).await?;
    assert!(shown >= 3, "visemes shown: {shown}");
    let png = browser.screenshot(&tab).await?;
    std::fs::write(agent_tests::artifacts_dir().join("pipeline-code.png"), &png)?;
    browser.quit().await;

    // The vision module's stage times reached /metrics, read by Prometheus's own parser.
    let samples = agent_tests::metrics::parse(&agent_tests::metrics::scrape(&agent).await?).await?;
    for stage in ["decode", "faces", "total"] {
        let n = agent_tests::metrics::value(
            &samples,
            "agent_vision_stage_seconds_count",
            &[("stage", stage)],
        );
        assert!(n > Some(5.0), "vision stage {stage} counted {n:?} times");
    }
    Ok(())
}
