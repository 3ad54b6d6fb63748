//! End-to-end tests of the browser agent: the real page in headless Chromium with fake media devices playing
//! recorded fixtures, the real robot-agent, assertions on hub channels and on the page's `window.agentDebug`.
//!
//! Needs `chromium` and `ffmpeg` (Debian packages) and a built `robot-agent` (`cargo build -p robot-agent`).

use agent_contract::channels as ch;
use std::path::Path;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use agent_tests::browser_chromium::{Chromium, Devices, FakeMedia, Tab};
use agent_tests::browser_link::{post_session, start_link_only};
use agent_tests::browser_media::{
    TONE_HZ, best_loop_correlation, envelope, jpeg_shape, pcm_samples, prepare, read_wav,
    spectrum_peak, speech_fixture,
};
use agent_tests::{Agent, DataDir, PATIENCE};
use anyhow::{Context, bail, ensure};
use serde_json::json;

const PAGE_READY: Duration = Duration::from_secs(30);

/// One browser at a time: the tests of this file run in parallel threads, and several Chromiums encoding video on a
/// 2-core machine would measure the machine, not the page.
static ONE_BROWSER: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());
const RATE: usize = 22050;

/// Converted fixtures, shared by the test processes in cargo's folder for them (a temporary folder per process,
/// never dropped from a static, left 42 MB in /tmp per test).
fn media() -> &'static (FakeMedia, FakeMedia) {
    static MEDIA: OnceLock<(FakeMedia, FakeMedia)> = OnceLock::new();
    MEDIA.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("browser-fixtures");
        prepare(&dir).expect("converting fixtures with ffmpeg")
    })
}

/// The page's URL in kiosk mode (microphone and camera start on their own; no echo cancellation, so the fixture
/// reaches the hub as recorded).
fn kiosk_url(agent: &Agent) -> String {
    agent.page_url("autostart=1&aec=0")
}

/// Waits until the page holds the role and has sent at least one camera frame and one audio chunk.
async fn wait_streaming(browser: &Chromium, tab: &Tab) -> anyhow::Result<()> {
    browser
        .wait_for(
            tab,
            "window.agentDebug && agentDebug.role === 'holder' && agentDebug.sent.video > 0 && agentDebug.sent.audio > 0",
            PAGE_READY,
        )
        .await
}

/// Receives from `sub` until `duration` has passed, returning (hub timestamp µs, payload) pairs.
async fn collect(sub: &flow::Subscription, duration: Duration) -> Vec<(u64, bytes::Bytes)> {
    let mut out = Vec::new();
    let deadline = tokio::time::Instant::now() + duration;
    while let Ok(Some(d)) = tokio::time::timeout_at(deadline, sub.recv()).await {
        out.push((d.ts_us, d.payload));
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn page_streams_microphone_and_camera_into_hub_and_obeys_avatar_commands()
-> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    let (speech, _) = media();
    let data = DataDir::new()?;
    let agent = start_link_only(&data).await?;
    let hub = agent.client("browser-test").await?;
    // Sticky subscriptions: they start delivering when the page's role creates the channels.
    let audio = hub.subscribe(ch::AUDIO.name).await?;
    let video = hub.subscribe(ch::VIDEO.name).await?;
    let grey = hub.subscribe(ch::VIDEO_Y.name).await?;
    let ctrl = hub.subscribe(ch::CTRL.name).await?;
    let avatar = hub
        .publisher(ch::AVATAR.name, r#"{"format":"json"}"#)
        .await?;
    let detections = hub
        .publisher(ch::DETECTIONS.name, r#"{"format":"json"}"#)
        .await?;

    let browser = Chromium::launch(speech).await?;
    let tab = browser.open(&kiosk_url(&agent)).await?;
    wait_streaming(&browser, &tab).await?;
    // The channel headers say what flows.
    let info = hub.channel(ch::AUDIO.name).await?;
    let header: serde_json::Value = serde_json::from_str(&info.header)?;
    assert_eq!(
        (header["format"].as_str(), header["rate"].as_u64()),
        (Some("s16le"), Some(22050))
    );

    // Let the pipeline settle, then measure 6 s of everything at once.
    tokio::time::sleep(Duration::from_millis(1500)).await;
    while audio.try_recv().is_some() {}
    while video.try_recv().is_some() {}
    while grey.try_recv().is_some() {}
    let window = Duration::from_secs(6);
    let (a, v, y) = tokio::join!(
        collect(&audio, window),
        collect(&video, window),
        collect(&grey, window)
    );

    // Audio: 20 ms chunks of 22050 Hz PCM, at the real-time rate, carrying the fixture's speech envelope.
    ensure!(a.len() > 200, "only {} audio chunks in 6 s", a.len());
    for (_, chunk) in &a {
        ensure!(
            chunk.len() == 882,
            "audio chunk of {} bytes (expected 441 samples = 20 ms)",
            chunk.len()
        );
    }
    let samples: Vec<i16> = a.iter().flat_map(|(_, c)| pcm_samples(c)).collect();
    let secs = samples.len() as f64 / RATE as f64;
    ensure!(
        (5.0..=7.0).contains(&secs),
        "{secs:.2} s of audio arrived in a 6 s window"
    );
    let (fixture_rate, fixture) = read_wav(&speech_fixture())?;
    assert_eq!(fixture_rate as usize, RATE);
    let window_samples = RATE / 20; // 50 ms
    let reference = envelope(&fixture, window_samples);
    let captured = envelope(&samples, window_samples);
    let r = best_loop_correlation(&reference, &captured);
    println!(
        "audio: {} chunks, {secs:.2} s, envelope correlation with the fixture {r:.3}",
        a.len()
    );
    ensure!(
        r > 0.8,
        "captured audio's energy envelope does not match the fixture's speech (r = {r:.3})"
    );

    // Video: 640x360 colour JPEGs at 12-16 fps (hub timestamps).
    ensure!(v.len() >= 10, "only {} video frames", v.len());
    let span_s = (v[v.len() - 1].0 - v[0].0) as f64 / 1e6;
    let fps = (v.len() - 1) as f64 / span_s;
    let page = browser
        .eval(&tab, "JSON.stringify(agentDebug.snapshot)")
        .await?;
    println!("video: {} frames, {fps:.1} fps; page: {page}", v.len());
    ensure!((12.0..=16.0).contains(&fps), "video at {fps:.1} fps");
    for (_, jpeg) in v.iter().step_by(10) {
        let (w, h, ch) = jpeg_shape(jpeg)?;
        ensure!(
            (w, h, ch) == (640, 360, 3),
            "video frame is {w}x{h} with {ch} channels"
        );
    }
    // Y frames: the same size, one channel.
    ensure!(y.len() >= 10, "only {} Agent.video.y frames", y.len());
    for (_, jpeg) in y.iter().step_by(10) {
        let (w, h, ch) = jpeg_shape(jpeg)?;
        ensure!(
            (w, h, ch) == (640, 360, 1),
            "Y frame is {w}x{h} with {ch} channels"
        );
    }

    // The page blinks by itself before the server drives it...
    let before: u64 = serde_json::from_value(browser.eval(&tab, "agentDebug.blinks").await?)?;
    browser
        .wait_for(
            &tab,
            &format!("agentDebug.blinks > {before}"),
            Duration::from_secs(10),
        )
        .await?;
    assert_eq!(
        browser.eval(&tab, "agentDebug.blinkOwner").await?,
        json!("page")
    );
    // ...and obeys a server blink: the eyelid closes (sampled every 100 ms during a long hold), then reopens.
    let blinks: u64 = serde_json::from_value(browser.eval(&tab, "agentDebug.blinks").await?)?;
    avatar
        .publish(r#"{"cmd":"blink","close_ms":80,"hold_ms":600,"open_ms":200}"#)
        .await?;
    browser
        .wait_for(&tab, "agentDebug.eyelid < 0.05", Duration::from_secs(5))
        .await?;
    browser
        .wait_for(
            &tab,
            &format!("agentDebug.blinks > {blinks} && agentDebug.eyelid > 0.9"),
            Duration::from_secs(5),
        )
        .await?;
    assert_eq!(
        browser.eval(&tab, "agentDebug.blinkOwner").await?,
        json!("server")
    );

    // Gaze: a target on the right of the camera image is the avatar's left: eyes and head turn to the viewer's left.
    avatar
        .publish(r#"{"cmd":"gaze","x":0.9,"y":0.3,"source":"face"}"#)
        .await?;
    browser
        .wait_for(
            &tab,
            "agentDebug.gaze.x === 0.9 && agentDebug.gaze.y === 0.3",
            Duration::from_secs(5),
        )
        .await?;
    browser
        .wait_for(
            &tab,
            "agentDebug.eyeOffset.x < -0.6 && agentDebug.head.yaw < -0.2",
            Duration::from_secs(5),
        )
        .await?;
    avatar.publish(r#"{"cmd":"gaze","x":0.1,"y":0.5}"#).await?;
    browser
        .wait_for(
            &tab,
            "agentDebug.eyeOffset.x > 0.6 && agentDebug.head.yaw > 0.2",
            Duration::from_secs(5),
        )
        .await?;

    // Detections reach the overlay; mood changes the expression.
    // (the contract's shape; tests/pipeline.rs has the real vision module produce them)
    let frame = json!({"seq": 1, "ts_us": 0, "width": 640, "height": 360});
    let seen = json!({"frame": frame, "faces": [{"x": 300, "y": 80, "w": 90, "h": 90}],
        "motion": {"frame": frame, "moving": true, "centre": {"x": 420.0, "y": 200.0}, "regions": []},
        "codes": [{"kind": "qr", "text": "https://example.org", "hex": "", "appearance": 1, "new": true,
            "polygon": [{"x": 40.0, "y": 40.0}, {"x": 140.0, "y": 40.0}, {"x": 140.0, "y": 140.0}, {"x": 40.0, "y": 140.0}]}]});
    let _: agent_contract::detections::DetectionsMsg = serde_json::from_value(seen.clone())?;
    detections.publish(seen.to_string()).await?;
    avatar.publish(r#"{"cmd":"mood","mood":"happy"}"#).await?;
    browser
        .wait_for(
            &tab,
            "agentDebug.detections > 0 && agentDebug.overlayItems === 3 && agentDebug.mood === 'happy'",
            Duration::from_secs(5),
        )
        .await?;

    // Speech: framed PCM of one utterance plays through WebAudio, and its visemes follow the audio clock.
    let speech = hub
        .publisher(
            ch::SPEECH.name,
            r#"{"format":"s16le","rate":22050,"channels":1,"framing":"utterance-offset"}"#,
        )
        .await?;
    let (_, voice) = read_wav(&agent_tests::fixtures::fixture("audio/LJ001-0002.wav")?)?;
    let utterance: u32 = 7;
    avatar
        .publish(
            json!({"cmd": "visemes", "utterance": utterance, "items": [
                {"t_ms": 0, "v": "sil"}, {"t_ms": 100, "v": "aa"}, {"t_ms": 500, "v": "O"},
                {"t_ms": 900, "v": "E"}, {"t_ms": 1300, "v": "PP"}, {"t_ms": 1700, "v": "sil"}]})
            .to_string(),
        )
        .await?;
    for (i, chunk) in voice.chunks(RATE / 5).enumerate() {
        let mut payload = utterance.to_le_bytes().to_vec();
        payload.extend_from_slice(&((i * RATE / 5) as u32).to_le_bytes());
        payload.extend(chunk.iter().flat_map(|s| s.to_le_bytes()));
        speech.publish(payload).await?;
    }
    browser
        .wait_for(
            &tab,
            "agentDebug.speechChunks >= 9",
            Duration::from_secs(10),
        )
        .await?;
    // The mouth opens for "aa"/"O" while the utterance plays, then closes again (to the happy mood's rest).
    browser
        .wait_for(
            &tab,
            "agentDebug.viseme === 'O' && agentDebug.jaw > 0.3",
            Duration::from_secs(5),
        )
        .await?;
    browser
        .wait_for(
            &tab,
            "agentDebug.viseme === 'sil' && agentDebug.jaw < 0.15",
            Duration::from_secs(5),
        )
        .await?;

    // The holder's controls reach Agent.ctrl: switching listening off asks the ASR to stop.
    browser
        .wait_for(
            &tab,
            "!document.getElementById('asr-btn').disabled",
            Duration::from_secs(5),
        )
        .await?;
    browser
        .eval(&tab, "document.getElementById('asr-btn').click()")
        .await?;
    let sent = tokio::time::timeout(Duration::from_secs(5), ctrl.recv())
        .await
        .context("no Agent.ctrl message")?;
    let sent: serde_json::Value =
        serde_json::from_slice(&sent.context("Agent.ctrl ended")?.payload)?;
    assert_eq!(sent, json!({"asr": false}));

    // The artifact shows the overlay: detections again, and one more to be sure it is on screen.
    detections.publish(seen.to_string()).await?;
    browser
        .wait_for(&tab, "agentDebug.detections > 1", Duration::from_secs(5))
        .await?;
    let png = browser.screenshot(&tab).await?;
    std::fs::create_dir_all(agent_tests::artifacts_dir())?;
    let shot = agent_tests::artifacts_dir().join("browser-page.png");
    std::fs::write(&shot, &png).with_context(|| format!("writing {}", shot.display()))?;
    ensure!(png.len() > 10_000, "screenshot is only {} bytes", png.len());
    browser.quit().await;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn spectrum_peaks_at_the_test_tone() -> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    let (_, tone) = media();
    let data = DataDir::new()?;
    let agent = start_link_only(&data).await?;
    let hub = agent.client("fft-test").await?;
    let fft = hub.subscribe(ch::AUDIO_FFT.name).await?;
    let browser = Chromium::launch(tone).await?;
    let tab = browser.open(&kiosk_url(&agent)).await?;
    wait_streaming(&browser, &tab).await?;
    tokio::time::sleep(Duration::from_secs(1)).await;
    while fft.try_recv().is_some() {}
    let spectra = collect(&fft, Duration::from_secs(3)).await;
    ensure!(
        spectra.len() >= 40,
        "only {} spectra in 3 s (expected ~21/s)",
        spectra.len()
    );
    let bin_hz = RATE as f64 / 1024.0;
    let mut magnitudes = Vec::with_capacity(spectra.len());
    for (_, payload) in &spectra {
        ensure!(
            payload.len() == 512 * 4,
            "spectrum of {} bytes",
            payload.len()
        );
        let (hz, magnitude) = spectrum_peak(payload, RATE as f64, 1024);
        ensure!(
            (hz - TONE_HZ).abs() <= bin_hz,
            "spectrum peak at {hz:.1} Hz, tone is {TONE_HZ} Hz"
        );
        ensure!(
            magnitude <= 0.6,
            "tone magnitude {magnitude:.3} above half scale"
        );
        magnitudes.push(magnitude);
    }
    // The tone plays at half scale; the Hann window and resampling keep it within a couple of dB. A window that
    // straddles a capture glitch of the fake device (a busy machine) reads lower, so the median is what is checked.
    magnitudes.sort_by(|a, b| a.total_cmp(b));
    let median = magnitudes[magnitudes.len() / 2];
    ensure!(
        (0.3..=0.6).contains(&median),
        "median tone magnitude {median:.3}"
    );
    // Nobody subscribes to Agent.video.y in this test: the Y module stays idle while the camera streams.
    let y = hub.channel(ch::VIDEO_Y.name).await?;
    ensure!(
        y.stats.msgs == 0,
        "Agent.video.y produced {} frames with no subscriber",
        y.stats.msgs
    );
    let video = hub.channel(ch::VIDEO.name).await?;
    ensure!(video.stats.msgs > 0, "the camera was not streaming");
    // The page draws it: its own peak readout agrees.
    browser
        .wait_for(
            &tab,
            &format!("Math.abs(agentDebug.spectrumPeakHz - {TONE_HZ}) <= {bin_hz}"),
            Duration::from_secs(5),
        )
        .await?;
    browser.quit().await;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn second_tab_is_refused_the_role_and_takes_over_when_the_first_leaves() -> anyhow::Result<()>
{
    let _one = ONE_BROWSER.lock().await;
    let (speech, _) = media();
    let data = DataDir::new()?;
    let agent = start_link_only(&data).await?;
    let hub = agent.client("role-test").await?;
    let audio = hub.subscribe(ch::AUDIO.name).await?;
    let browser = Chromium::launch(speech).await?;
    let first = browser.open(&kiosk_url(&agent)).await?;
    wait_streaming(&browser, &first).await?;
    let second = browser.open(&kiosk_url(&agent)).await?;
    browser
        .wait_for(
            &second,
            "window.agentDebug && agentDebug.role === 'busy'",
            PAGE_READY,
        )
        .await?;
    let banner = browser
        .eval(
            &second,
            "document.getElementById('role-banner').textContent",
        )
        .await?;
    ensure!(
        banner
            .as_str()
            .is_some_and(|t| t.contains("Someone else is talking to the agent")),
        "banner says {banner}"
    );
    // While waiting, the second tab sends nothing and still shows the avatar.
    tokio::time::sleep(Duration::from_secs(1)).await;
    assert_eq!(
        browser
            .eval(&second, "agentDebug.sent.audio + agentDebug.sent.video")
            .await?,
        json!(0)
    );
    assert_eq!(
        browser.eval(&second, "agentDebug.connection").await?,
        json!("open")
    );

    browser.close(&first).await?;
    // The hub loses the first tab's channel, then the second tab's role recreates it.
    browser
        .wait_for(
            &second,
            "agentDebug.role === 'holder' && agentDebug.sent.audio > 0",
            PAGE_READY,
        )
        .await?;
    while audio.try_recv().is_some() {}
    let started = Instant::now();
    let got = tokio::time::timeout(Duration::from_secs(10), audio.recv())
        .await
        .context("no audio after takeover")?;
    ensure!(got.is_some(), "Agent.audio subscription ended");
    let owner = hub.channel(ch::AUDIO.name).await?.owner;
    println!(
        "takeover: audio flowing again {:?} after the check, channel owner {owner}",
        started.elapsed()
    );
    browser.quit().await;
    Ok(())
}

/// The page speaks the agent's language: with `agent.language = "it"` its controls read in Italian as soon as the
/// welcome arrives, and `?lang=en` keeps them in English.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_shows_its_controls_in_the_agents_language_unless_the_address_asks_for_another()
-> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    let data = DataDir::new()?;
    let opts = agent_tests::AgentOptions {
        config: Some(format!(
            "[agent]\nlanguage = \"it\"\n{}",
            agent_tests::browser_link::LINK_ONLY_CONFIG
        )),
        ..Default::default()
    };
    let agent = Agent::start_with(&data, opts).await?;
    let browser = Chromium::launch(&media().0).await?;
    for (query, language, label, spectrum) in [
        ("", "it", "Accendi il microfono", "Spettro del microfono"),
        ("lang=en", "en", "Start microphone", "Microphone spectrum"),
    ] {
        let tab = browser.open(&agent.page_url(query)).await?;
        browser
            .wait_for(
                &tab,
                &format!("window.agentDebug && agentDebug.welcomes > 0 && agentDebug.language === {language:?}"),
                PAGE_READY,
            )
            .await?;
        let shown = browser
            .eval(
                &tab,
                "[agentDebug.micLabel, document.documentElement.lang, document.querySelector('[data-words=spectrum]').textContent]",
            )
            .await?;
        ensure!(
            shown == json!([label, language, spectrum]),
            "{query:?}: the page shows {shown}"
        );
        browser.close(&tab).await?;
    }
    browser.quit().await;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn page_explains_denied_permission_and_missing_devices() -> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    let data = DataDir::new()?;
    let agent = start_link_only(&data).await?;
    for (devices, expected) in [
        (
            Devices::Denied,
            [
                "Permission to use the microphone was denied",
                "Permission to use the camera was denied",
            ],
        ),
        (
            Devices::Absent,
            ["No microphone was found", "No camera was found"],
        ),
    ] {
        let browser = Chromium::launch_with(&devices).await?;
        let tab = browser.open(&kiosk_url(&agent)).await?;
        let shown = "document.getElementById('notice').hidden === false";
        browser.wait_for(&tab, shown, PAGE_READY).await?;
        // Both devices fail; give the second failure a moment to be reported too.
        let both = format!(
            "document.getElementById('notice').textContent.includes({:?})",
            expected[1]
        );
        browser
            .wait_for(&tab, &both, Duration::from_secs(10))
            .await?;
        let text = browser
            .eval(&tab, "document.getElementById('notice').textContent")
            .await?;
        let text = text.as_str().unwrap_or_default().to_string();
        for e in expected {
            ensure!(text.contains(e), "{devices:?}: notice {text:?} lacks {e:?}");
        }
        // Nothing was captured, so the page gave the role back for someone else.
        browser
            .wait_for(
                &tab,
                "agentDebug.role === 'none' && !agentDebug.micRunning",
                Duration::from_secs(10),
            )
            .await?;
        browser.quit().await;
    }
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn link_refuses_foreign_origins_and_closes_on_malformed_frames() -> anyhow::Result<()> {
    use futures_util::{SinkExt, StreamExt};
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    use tokio_tungstenite::tungstenite::{Error as WsError, Message};

    let data = DataDir::new()?;
    let agent = start_link_only(&data).await?;
    let own = format!("http://{}", agent.http);
    let http = agent.http.to_string();
    // A cross-site page can neither get a session nor open the link.
    let page_token = agent.page_token().to_string();
    let (status, _) = post_session(&http, "http://evil.example", &page_token).await?;
    assert_eq!(status, 403);
    let (status, body) = post_session(&http, &own, &page_token).await?;
    assert_eq!(status, 200, "{body}");
    let session: serde_json::Value = serde_json::from_str(&body)?;
    let token = session["session"]
        .as_str()
        .context("no session in answer")?
        .to_string();

    let connect = |origin: &'static str, token: Option<&str>| {
        let url = match token {
            Some(t) => format!("ws://{http}/link?session={t}"),
            None => format!("ws://{http}/link"),
        };
        let bearer = format!("Bearer {page_token}");
        async move {
            let mut req = url.into_client_request()?;
            req.headers_mut().insert("Authorization", bearer.parse()?);
            if !origin.is_empty() {
                req.headers_mut().insert("Origin", origin.parse()?);
            }
            Ok::<_, anyhow::Error>(tokio_tungstenite::connect_async(req).await)
        }
    };
    let own_origin: &'static str = Box::leak(own.clone().into_boxed_str());
    for (origin, tok, why) in [
        (
            "http://evil.example",
            Some(token.as_str()),
            "foreign origin",
        ),
        ("", Some(token.as_str()), "no origin"),
        (own_origin, None, "no session"),
        (
            own_origin,
            Some("00000000000000000000000000000000"),
            "unknown session",
        ),
    ] {
        match connect(origin, tok).await? {
            Err(WsError::Http(res)) => assert_eq!(res.status().as_u16(), 403, "{why}"),
            Ok(_) => bail!("link accepted a socket with {why}"),
            Err(e) => bail!("{why}: unexpected error {e}"),
        }
    }

    // The real page's origin and session work; a malformed frame closes that socket with 1003 and a reason.
    let (mut ws, _) = connect(own_origin, Some(&token)).await??;
    let welcome = tokio::time::timeout(PATIENCE, ws.next())
        .await
        .context("no welcome in time")?
        .context("no welcome")??;
    let welcome: serde_json::Value = serde_json::from_str(welcome.to_text()?)?;
    assert_eq!(welcome["type"], "welcome");
    assert_eq!(welcome["audio"]["rate"], 22050);
    ws.send(Message::Binary(
        vec![0x02, 1, 0, 0, 0, 0, 0, 0, b'P', b'N', b'G'].into(),
    ))
    .await?;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(5);
    loop {
        match tokio::time::timeout_at(deadline, ws.next())
            .await
            .context("socket not closed")?
        {
            Some(Ok(Message::Close(Some(frame)))) => {
                assert_eq!(u16::from(frame.code), 1003);
                assert!(frame.reason.contains("JPEG"), "reason {:?}", frame.reason);
                break;
            }
            Some(Ok(_)) => continue,
            other => bail!("expected a close frame, got {other:?}"),
        }
    }
    // The same session may reconnect (the socket closed), and the server still serves others.
    let (mut again, _) = connect(own_origin, Some(&token)).await??;
    let msg = tokio::time::timeout(PATIENCE, again.next())
        .await
        .context("no welcome after reconnect in time")?
        .context("no welcome after reconnect")??;
    assert!(msg.to_text()?.contains("\"welcome\""));
    Ok(())
}
