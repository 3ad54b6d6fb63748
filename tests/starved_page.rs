//! A starved page loses nothing the microphone heard.
//!
//! The page's main thread is blocked most of the time by a busy loop injected into it, as a renderer starved by its
//! avatar or by other work on a small machine is. The capture worklet keeps producing 20 ms chunks on the audio
//! thread; the main thread forwards them late, in bursts. Every chunk must still reach the hub (late rather than
//! missing) and the real whisper-sat, started as `make run` starts it, must transcribe the spoken sentence whole:
//! in the run that found the defect, "How many people can you see?" arrived as "People can you see".
//!
//! Needs `chromium`, `ffmpeg` and the whisper model (`make test` provides them).

use std::time::Duration;

use agent_contract::channels as ch;
use agent_contract::transcript::TranscriptMessage;
use agent_tests::browser_chromium::{Chromium, FakeMedia};
use agent_tests::browser_media::{prepare, speech_fixture};
use agent_tests::spoken::words;
use agent_tests::{Agent, DataDir, PATIENCE, Satellite};
use anyhow::{Context, bail};

/// Blocks the page's main thread for 1.4 s of every 1.5 s: each block is longer than the whisper satellite's old
/// 0.8 s stall and the uplink's old one-second lane, the two places the first words went.
const STARVE: &str = "window.__starve = setInterval(() => { const t = performance.now(); \
                      while (performance.now() - t < 1400) {} }, 1500); true";
const UNSTARVE: &str = "clearInterval(window.__starve); true";
/// Whole passes of the sentence heard while starved before the test judges.
const PASSES: usize = 2;

/// The fixture's sentence (JFK: "And so my fellow Americans, ask not what your country can do for you, ask what
/// you can do for your country.") between 2 s and 3 s of silence, at a sound card's 48 kHz, looping.
fn question(dir: &std::path::Path) -> anyhow::Result<std::path::PathBuf> {
    let out = dir.join("starved-question.wav");
    let status = std::process::Command::new("ffmpeg")
        .args(["-loglevel", "error", "-y", "-i"])
        .arg(speech_fixture())
        .args([
            "-af",
            "adelay=2000,apad=pad_dur=3",
            "-ar",
            "48000",
            "-ac",
            "1",
        ])
        .arg(&out)
        .status()
        .context("running ffmpeg (apt-get install ffmpeg)")?;
    anyhow::ensure!(status.success(), "ffmpeg failed: {status}");
    Ok(out)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_starved_page_still_delivers_every_sample_and_the_question_is_heard_whole()
-> anyhow::Result<()> {
    let dir = tempfile::Builder::new().prefix("starved-page-").tempdir()?;
    let (camera, _) = prepare(dir.path())?;
    let media = FakeMedia {
        audio_wav: question(dir.path())?,
        video_y4m: camera.video_y4m,
    };
    let data = DataDir::new()?;
    // The embedded defaults, every module on, as `make run` starts it.
    let agent = Agent::start(&data).await?;
    let _ears = Satellite::start(&agent, "starved-ears").await?;
    let hub = agent.client("starved-watch").await?;
    // Sticky subscriptions: they deliver from the moment the page's role creates the channels.
    let audio = hub.subscribe(ch::AUDIO.name).await?;
    let transcripts = hub.subscribe(ch::TRANSCRIPT.name).await?;

    let browser = Chromium::launch(&media).await?;
    let tab = browser.open(&agent.page_url("autostart=1&aec=0")).await?;
    browser
        .wait_for(
            &tab,
            "window.agentDebug && agentDebug.role === 'holder' && agentDebug.sent.audio > 0",
            PATIENCE,
        )
        .await?;
    browser.eval(&tab, STARVE).await?;
    let starved_at_us = u64::try_from(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)?
            .as_micros(),
    )?;

    // Count every chunk the hub delivers while listening for the sentence, heard whole PASSES times.
    let mut chunks: u64 = 0;
    let mut heard: Vec<String> = Vec::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(120);
    let whole = loop {
        let passes = heard
            .iter()
            .filter(|t| t.contains("for your country"))
            .count();
        if passes >= PASSES {
            break true;
        }
        tokio::select! {
            d = audio.recv() => {
                d.context("Agent.audio subscription ended")?;
                chunks += 1;
            }
            t = transcripts.recv() => {
                let t = t.context("Agent.transcript subscription ended")?;
                // The channel also carries voice-activity events: only transcripts have a text.
                let Ok(msg) = serde_json::from_slice::<TranscriptMessage>(&t.payload) else {
                    continue;
                };
                // Speech that began before the page was starved is not this test's question.
                if msg.is_final && msg.start_us > starved_at_us {
                    println!("heard while starved: {:?}", msg.text);
                    heard.push(words(&msg.text));
                }
            }
            _ = tokio::time::sleep_until(deadline) => break false,
        }
    };
    browser.eval(&tab, UNSTARVE).await?;
    if !whole {
        bail!(
            "the sentence was not heard {PASSES} times in 120 s while the page was starved: {heard:?}"
        );
    }
    // The sentence's opening heard in one piece while starved: before the fix every late burst restarted the
    // stream, and no pass ever kept "and so my fellow americans" together ("and so my" / "they fell in america").
    // On a machine loaded by the whole test suite an occasional pass may still lose a burst to the hub's
    // per-subscriber queue (a hole restarts the stream), so one whole opening is asserted, not every pass.
    assert!(
        heard.iter().any(|t| t.contains("so my fellow americans")),
        "the sentence never kept its first words while the page was starved: {heard:?}"
    );

    // Nothing lost between the capture and the hub: every chunk the page sent arrived, and none was dropped on the
    // server's side of the link. The page is no longer starved, so its last chunks follow within moments.
    let sent = browser.eval(&tab, "agentDebug.sent.audio").await?;
    let sent = sent.as_u64().context("agentDebug.sent.audio")?;
    let deadline = tokio::time::Instant::now() + PATIENCE;
    while chunks < sent {
        match tokio::time::timeout_at(deadline, audio.recv()).await {
            Ok(Some(_)) => chunks += 1,
            Ok(None) => {
                bail!("Agent.audio ended after {chunks} of the {sent} chunks the page sent")
            }
            Err(_) => bail!("the page sent {sent} audio chunks, the hub delivered {chunks}"),
        }
    }
    let dropped = browser.eval(&tab, "agentDebug.audioDropped").await?;
    assert_eq!(
        dropped.as_u64(),
        Some(0),
        "the server dropped audio chunks from the page"
    );
    browser.quit().await;
    Ok(())
}
