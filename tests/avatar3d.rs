//! End-to-end tests of the avatar's two renderers, the 3D head (`?avatar=3d`, three.js on SwiftShader's software
//! WebGL; the page's own choice only on a GPU) and the 2D canvas face (the page's choice on software WebGL, and
//! `?avatar=2d`): the same commands move both alike; the 3D head's
//! mouth follows the viseme schedule on the audio clock, its eyes turn towards the gaze target, it blinks at the
//! specified intervals and phases; without WebGL the page falls back to the 2D face. Screenshots of both
//! renderers (rest, smile, thinking, listening, surprise, visemes "aa" "O" "FF" "PP" "SS", blinking, looking left
//! and right; the 3D head also from three-quarters) and a side-by-side sheet of them go to `artifacts/`.
//!
//! Needs `chromium`, `ffmpeg`, `node` and a built `robot-agent`, like tests/browser.rs.

use agent_contract::channels as ch;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

use agent_tests::browser_chromium::{Chromium, Devices, FakeMedia, Tab};
use agent_tests::browser_link::start_link_only;
use agent_tests::browser_media::prepare;
use agent_tests::{Agent, DataDir};
use anyhow::{Context, ensure};
use serde::Deserialize;
use serde_json::{Value, json};

const RATE: usize = 22050;
const PAGE_READY: Duration = Duration::from_secs(40);
/// Software WebGL without the deprecation fallback, as a GPU-less user's Chromium gets it.
const WEBGL: &[&str] = &["--enable-unsafe-swiftshader"];

/// One browser at a time (as in tests/browser.rs): SwiftShader renders on the CPU, and two pages drawing at once on
/// a 2-core machine would measure the machine.
static ONE_BROWSER: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

fn media() -> &'static FakeMedia {
    static MEDIA: OnceLock<FakeMedia> = OnceLock::new();
    MEDIA.get_or_init(|| {
        // Shared with tests/browser.rs, in cargo's folder for test files (not a temporary folder per process, which
        // a static never drops).
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("browser-fixtures");
        prepare(&dir).expect("converting fixtures with ffmpeg").0
    })
}

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The page of `agent` with renderer `renderer` ("2d", "3d", "3d-full": the 3D head with the settings it uses on a
/// GPU, for screenshots, "3d-full-3q": the same seen from three-quarters, or "default": no `avatar` parameter), in
/// kiosk mode as tests/browser.rs opens it.
fn page(agent: &Agent, renderer: &str) -> String {
    match renderer {
        "2d" => agent.page_url("autostart=1&aec=0&avatar=2d"),
        "3d-full" => agent.page_url("autostart=1&aec=0&avatar=3d&avatarquality=full"),
        "3d-full-3q" => {
            agent.page_url("autostart=1&aec=0&avatar=3d&avatarquality=full&avatarview=0.62")
        }
        "default" => agent.page_url("autostart=1&aec=0"),
        _ => agent.page_url("autostart=1&aec=0&avatar=3d"),
    }
}

/// A browser and a page showing `renderer`, with the hub publishers the tests drive the avatar through.
struct Stage {
    browser: Chromium,
    tab: Tab,
    avatar: flow::Publisher,
    speech: flow::Publisher,
    _hub: flow::Client,
    _agent: Agent,
    _data: DataDir,
}

impl Stage {
    async fn open(renderer: &str, flags: &[&str]) -> anyhow::Result<Stage> {
        let data = DataDir::new()?;
        let agent = start_link_only(&data).await?;
        let hub = agent.client("avatar3d-test").await?;
        let avatar = hub
            .publisher(ch::AVATAR.name, r#"{"format":"json"}"#)
            .await?;
        let speech = hub
            .publisher(
                ch::SPEECH.name,
                r#"{"format":"s16le","rate":22050,"channels":1,"framing":"utterance-offset"}"#,
            )
            .await?;
        let browser =
            Chromium::launch_with_flags(&Devices::Granted(media().clone()), flags).await?;
        let tab = browser.open(&page(&agent, renderer)).await?;
        browser
            .wait_for(
                &tab,
                "window.agentDebug && agentDebug.role === 'holder' && agentDebug.avatarRenderer !== undefined",
                PAGE_READY,
            )
            .await?;
        // Let the renderer warm up (SwiftShader compiles each material's shaders on first use, which stalls the
        // first frames for seconds), so the tests' timing starts on a running animation.
        browser
            .wait_for(
                &tab,
                "agentDebug.avatarFrameMs.length > 40",
                Duration::from_secs(60),
            )
            .await?;
        Ok(Stage {
            browser,
            tab,
            avatar,
            speech,
            _hub: hub,
            _agent: agent,
            _data: data,
        })
    }

    async fn eval(&self, expr: &str) -> anyhow::Result<Value> {
        self.browser.eval(&self.tab, expr).await
    }

    async fn wait(&self, expr: &str, secs: u64) -> anyhow::Result<()> {
        self.browser
            .wait_for(&self.tab, expr, Duration::from_secs(secs))
            .await
    }

    async fn command(&self, cmd: Value) -> anyhow::Result<()> {
        self.avatar.publish(cmd.to_string()).await?;
        Ok(())
    }

    /// Plays `seconds` of quiet PCM as utterance `utterance` after sending its `visemes`.
    async fn speak(&self, utterance: u32, visemes: Value, seconds: f64) -> anyhow::Result<()> {
        self.command(json!({"cmd": "visemes", "utterance": utterance, "items": visemes}))
            .await?;
        let total = (seconds * RATE as f64) as usize;
        let chunk = RATE / 5;
        let mut offset = 0;
        while offset < total {
            let n = chunk.min(total - offset);
            let mut payload = utterance.to_le_bytes().to_vec();
            payload.extend_from_slice(&(offset as u32).to_le_bytes());
            // A faint tone, not digital silence, so nothing along the way can skip it as empty.
            payload.extend((0..n).flat_map(|i| {
                let t = (offset + i) as f64 / RATE as f64;
                (((t * 220.0 * std::f64::consts::TAU).sin() * 300.0) as i16).to_le_bytes()
            }));
            self.speech.publish(payload).await?;
            offset += n;
        }
        Ok(())
    }

    async fn shot(&self, name: &str) -> anyhow::Result<()> {
        let png = self.browser.screenshot_of(&self.tab, ".stage").await?;
        ensure!(
            png.len() > 5_000,
            "screenshot {name} is only {} bytes",
            png.len()
        );
        std::fs::create_dir_all(agent_tests::artifacts_dir())?;
        let path = agent_tests::artifacts_dir().join(format!("{name}.png"));
        std::fs::write(&path, &png).with_context(|| format!("writing {}", path.display()))?;
        println!("screenshot: {}", path.display());
        Ok(())
    }

    async fn quit(self) {
        self.browser.quit().await;
    }
}

/// The avatar assertions of tests/browser.rs, on one renderer: page blinks, a server blink closes and reopens the
/// lids, gaze turns eyes and head, mood changes, visemes open and close the mouth on the audio clock.
async fn commands_move_the_avatar(renderer: &str) -> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    let s = Stage::open(renderer, WEBGL).await?;
    assert_eq!(s.eval("agentDebug.avatarRenderer").await?, json!(renderer));

    let before: u64 = serde_json::from_value(s.eval("agentDebug.blinks").await?)?;
    s.wait(&format!("agentDebug.blinks > {before}"), 10).await?;
    assert_eq!(s.eval("agentDebug.blinkOwner").await?, json!("page"));
    let blinks: u64 = serde_json::from_value(s.eval("agentDebug.blinks").await?)?;
    s.command(json!({"cmd": "blink", "close_ms": 80, "hold_ms": 600, "open_ms": 200}))
        .await?;
    s.wait("agentDebug.eyelid < 0.05", 5).await?;
    s.wait(
        &format!("agentDebug.blinks > {blinks} && agentDebug.eyelid > 0.9"),
        5,
    )
    .await?;
    assert_eq!(s.eval("agentDebug.blinkOwner").await?, json!("server"));

    s.command(json!({"cmd": "gaze", "x": 0.9, "y": 0.3, "source": "face"}))
        .await?;
    s.wait("agentDebug.gaze.x === 0.9 && agentDebug.gaze.y === 0.3", 5)
        .await?;
    s.wait(
        "agentDebug.eyeOffset.x < -0.6 && agentDebug.head.yaw < -0.2",
        5,
    )
    .await?;
    s.command(json!({"cmd": "gaze", "x": 0.1, "y": 0.5}))
        .await?;
    s.wait(
        "agentDebug.eyeOffset.x > 0.6 && agentDebug.head.yaw > 0.2",
        5,
    )
    .await?;

    s.command(json!({"cmd": "mood", "mood": "happy"})).await?;
    s.wait("agentDebug.mood === 'happy'", 5).await?;

    s.speak(
        7,
        json!([{"t_ms": 0, "v": "sil"}, {"t_ms": 100, "v": "aa"}, {"t_ms": 500, "v": "O"},
               {"t_ms": 900, "v": "E"}, {"t_ms": 1300, "v": "PP"}, {"t_ms": 1700, "v": "sil"}]),
        2.0,
    )
    .await?;
    s.wait("agentDebug.viseme === 'O' && agentDebug.jaw > 0.3", 8)
        .await?;
    s.wait("agentDebug.viseme === 'sil' && agentDebug.jaw < 0.15", 8)
        .await?;
    s.quit().await;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_2d_face_obeys_the_avatar_commands() -> anyhow::Result<()> {
    commands_move_the_avatar("2d").await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_3d_head_obeys_the_same_avatar_commands() -> anyhow::Result<()> {
    commands_move_the_avatar("3d").await
}

#[derive(Debug, Deserialize)]
struct Frame {
    /// Page time (ms), audio clock (s), mouth opening read back from the mesh's morph influences.
    t: f64,
    a: f64,
    open: f64,
    blink: f64,
}

#[derive(Debug, Deserialize)]
struct Batch {
    #[serde(rename = "startS")]
    start_s: f64,
    items: Vec<Cue>,
}

#[derive(Debug, Deserialize)]
struct Cue {
    t_ms: f64,
    v: String,
}

/// The 2D face's jaw per viseme (web/js/avatar/visemes.js): what the mouth opening must show for each cue.
fn jaw_of(v: &str) -> f64 {
    match v {
        "FF" | "SS" => 0.1,
        "TH" | "nn" => 0.2,
        "DD" => 0.25,
        "kk" => 0.32,
        "CH" | "RR" => 0.22,
        "aa" => 0.85,
        "E" => 0.5,
        "I" | "U" => 0.3,
        "O" => 0.6,
        _ => 0.0,
    }
}

async fn trace(s: &Stage) -> anyhow::Result<Vec<Frame>> {
    Ok(serde_json::from_value(
        s.eval("agentDebug.avatarTrace").await?,
    )?)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_3d_mouth_follows_the_viseme_schedule_within_40_ms_of_the_audio_clock()
-> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    let s = Stage::open("3d", WEBGL).await?;
    ensure!(s.eval("agentDebug.avatarRenderer").await? == json!("3d"));
    let cues = json!([{"t_ms": 0, "v": "sil"}, {"t_ms": 200, "v": "aa"}, {"t_ms": 700, "v": "PP"},
        {"t_ms": 1100, "v": "O"}, {"t_ms": 1600, "v": "FF"}, {"t_ms": 2000, "v": "E"},
        {"t_ms": 2400, "v": "U"}, {"t_ms": 2800, "v": "kk"}, {"t_ms": 3200, "v": "sil"}]);
    s.speak(11, cues, 3.5).await?;
    s.wait("agentDebug.visemeSchedule.length > 0", 8).await?;
    let batches: Vec<Batch> = serde_json::from_value(s.eval("agentDebug.visemeSchedule").await?)?;
    let batch = batches.last().context("no viseme batch")?;
    let steps: Vec<(f64, f64)> = batch
        .items
        .iter()
        .map(|c| (batch.start_s + c.t_ms / 1000.0, jaw_of(&c.v)))
        .collect();
    let first = steps[0].0;
    let last = steps[steps.len() - 1].0;
    s.wait(
        &format!("agentDebug.avatarTrace.at(-1).a > {}", last + 0.4),
        10,
    )
    .await?;

    // The expected opening is a step function of audio time; the mesh must be within the range the steps take
    // in a 40 ms window around each frame's audio time: blending may lead or lag a cue by no more than that.
    let expected = |a: f64| {
        let mut j = 0.0;
        for &(at, jaw) in &steps {
            if at <= a {
                j = jaw;
            }
        }
        j
    };
    // The page's audio clock starts over when speech first plays: only frames after its last restart count.
    let all = trace(&s).await?;
    let restart = (1..all.len())
        .rev()
        .find(|&i| all[i].a < all[i - 1].a)
        .unwrap_or(0);
    let frames: Vec<Frame> = all
        .into_iter()
        .skip(restart)
        .filter(|f| f.a >= first - 0.1 && f.a <= last + 0.3)
        .collect();
    // Software WebGL on a busy machine may draw only ~10 frames a second; each one is checked.
    ensure!(
        frames.len() >= 15,
        "only {} frames drawn during 3.5 s of speech",
        frames.len()
    );
    for f in &frames {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        let mut x = f.a - 0.04;
        while x <= f.a + 0.04 + 1e-9 {
            lo = lo.min(expected(x));
            hi = hi.max(expected(x));
            x += 0.002;
        }
        let off = if f.open < lo - 0.01 {
            lo - f.open
        } else if f.open > hi + 0.01 {
            f.open - hi
        } else {
            0.0
        };
        ensure!(
            off == 0.0,
            "at audio {:.3} s the mouth is open {:.3}, the schedule allows {lo:.2}..{hi:.2} within 40 ms \
             (schedule {steps:?}; frames {:?})",
            f.a,
            f.open,
            frames.iter().map(|f| (f.a, f.open)).collect::<Vec<_>>()
        );
    }
    // Not vacuous: the mouth really opened wide for "aa" and closed for "PP".
    ensure!(
        frames.iter().any(|f| f.open > 0.8),
        "the mouth never opened for aa"
    );
    ensure!(
        frames
            .iter()
            .any(|f| f.a > steps[2].0 + 0.05 && f.a < steps[3].0 - 0.02 && f.open < 0.05),
        "the mouth never closed for PP"
    );
    println!("{} frames checked against the schedule", frames.len());
    s.quit().await;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_3d_eyes_rotate_towards_the_gaze_target_and_lead_the_head() -> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    let s = Stage::open("3d", WEBGL).await?;
    ensure!(s.eval("agentDebug.avatarRenderer").await? == json!("3d"));
    // Image-right is the avatar's left: the viewer's left, a negative yaw in three.js's frame.
    s.command(json!({"cmd": "gaze", "x": 0.9, "y": 0.5}))
        .await?;
    s.wait("agentDebug.eyeRotation.yaw < -0.15", 5).await?;
    // The eyes get there first; the head is still turning a moment later.
    let early: Value = s
        .eval("[agentDebug.eyeRotation.yaw, agentDebug.headRotation.yaw]")
        .await?;
    s.wait("agentDebug.headRotation.yaw < -0.1", 5).await?;
    let e: Vec<f64> = serde_json::from_value(early)?;
    ensure!(
        e[0].abs() > e[1].abs(),
        "eyes at {:.3} rad, head already at {:.3} rad",
        e[0],
        e[1]
    );
    s.command(json!({"cmd": "gaze", "x": 0.1, "y": 0.5}))
        .await?;
    s.wait(
        "agentDebug.eyeRotation.yaw > 0.15 && agentDebug.headRotation.yaw > 0.1",
        5,
    )
    .await?;
    // Lower in the image is looking down: a positive pitch.
    s.command(json!({"cmd": "gaze", "x": 0.5, "y": 0.95}))
        .await?;
    s.wait("agentDebug.eyeRotation.pitch > 0.1", 5).await?;
    s.command(json!({"cmd": "gaze", "x": 0.5, "y": 0.05}))
        .await?;
    s.wait("agentDebug.eyeRotation.pitch < -0.1", 5).await?;
    s.quit().await;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_3d_head_blinks_every_450_ms_to_4_s_in_close_hold_open_phases() -> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    let s = Stage::open("3d", WEBGL).await?;
    ensure!(s.eval("agentDebug.avatarRenderer").await? == json!("3d"));
    // The page's own blinks: each begins 450 ms to 4 s after the previous one ended (the page schedules the next
    // blink at the frame that ends one; it starts at the first frame after its time, hence the upper margin).
    s.wait(
        "agentDebug.blinkLog.filter((b) => b[1] !== null).length >= 6",
        40,
    )
    .await?;
    let log: Vec<(f64, Option<f64>)> =
        serde_json::from_value(s.eval("agentDebug.blinkLog").await?)?;
    let done: Vec<(f64, f64)> = log
        .iter()
        .filter_map(|&(start, end)| end.map(|e| (start, e)))
        .collect();
    ensure!(done.len() >= 6, "only {} blinks: {log:?}", done.len());
    for w in done.windows(2) {
        let gap = w[1].0 - w[0].1;
        ensure!(
            (449.0..=4300.0).contains(&gap),
            "{gap:.0} ms between the end of a blink and the next (blinks {done:?})"
        );
    }
    // A server blink with long, distinct phases: every frame drawn during it shows the lid where the close (ease
    // in), hold and open (ease out) curves put it at that frame's time, whatever the frame rate.
    let (close, hold, open) = (150.0, 300.0, 450.0);
    s.command(json!({"cmd": "blink", "close_ms": close, "hold_ms": hold, "open_ms": open}))
        .await?;
    s.wait("agentDebug.blinkOwner === 'server'", 5).await?;
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let log: Vec<(f64, Option<f64>)> =
        serde_json::from_value(s.eval("agentDebug.blinkLog").await?)?;
    let start = log.last().context("no blink logged")?.0;
    let openness = |t: f64| {
        let t = t - start;
        if t < close {
            let k = (t / close).max(0.0);
            1.0 - k * k
        } else if t < close + hold {
            0.0
        } else if t < close + hold + open {
            let k = (t - close - hold) / open;
            1.0 - (1.0 - k) * (1.0 - k)
        } else {
            1.0
        }
    };
    let during: Vec<Frame> = trace(&s)
        .await?
        .into_iter()
        .filter(|f| f.t >= start && f.t <= start + close + hold + open)
        .collect();
    ensure!(
        during.len() >= 4,
        "only {} frames during a 900 ms blink",
        during.len()
    );
    for f in &during {
        let want = 1.0 - openness(f.t);
        // Looking down (idle glances) closes the lids by up to a few hundredths more.
        ensure!(
            f.blink >= want - 0.03 && f.blink <= want + 0.06,
            "{:.0} ms into the blink the lid morph is {:.3}, the phases say {want:.3}",
            f.t - start,
            f.blink
        );
    }
    ensure!(
        during.iter().any(|f| f.blink > 0.95),
        "the lids never closed during the blink"
    );
    println!(
        "server blink: {} frames on the close/hold/open curve",
        during.len()
    );
    s.quit().await;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_without_webgl_falls_back_to_the_2d_face() -> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    // The 3D head asked for: without WebGL the page must show the 2D face instead.
    let s = Stage::open("3d", &["--disable-3d-apis"]).await?;
    assert_eq!(s.eval("agentDebug.avatarRenderer").await?, json!("2d"));
    assert_eq!(
        s.eval("!!document.createElement('canvas').getContext('webgl2')")
            .await?,
        json!(false)
    );
    // The 2D face is alive: it blinks and follows the gaze.
    let before: u64 = serde_json::from_value(s.eval("agentDebug.blinks").await?)?;
    s.wait(&format!("agentDebug.blinks > {before}"), 10).await?;
    s.command(json!({"cmd": "gaze", "x": 0.9, "y": 0.5}))
        .await?;
    s.wait("agentDebug.eyeOffset.x < -0.6", 5).await?;
    s.quit().await;
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn on_software_webgl_a_page_shows_the_2d_face_by_itself_and_the_3d_head_when_asked()
-> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    // Headless Chromium's WebGL is SwiftShader: the 3D head would take a core of the agent's machine.
    let s = Stage::open("default", WEBGL).await?;
    assert_eq!(s.eval("agentDebug.avatarRenderer").await?, json!("2d"));
    let reason = s.eval("agentDebug.avatarReason").await?;
    assert!(
        reason
            .as_str()
            .is_some_and(|r| r.contains("software rasteriser")),
        "{reason}"
    );
    s.quit().await;
    // Asked for, the 3D head is the lite model there, drawn and moving.
    let s = Stage::open("3d", WEBGL).await?;
    assert_eq!(s.eval("agentDebug.avatarRenderer").await?, json!("3d"));
    let (model, software, triangles) = drawn(&s).await?;
    assert_eq!(model, "assets/avatar-lite.glb");
    assert_eq!(software, Some(true));
    assert!(triangles > 0, "the 3D head drew no triangles");
    s.quit().await;
    let s = Stage::open("2d", WEBGL).await?;
    assert_eq!(s.eval("agentDebug.avatarRenderer").await?, json!("2d"));
    s.quit().await;
    Ok(())
}

/// Drawings the page's frame clock has made since it loaded (`agentDebug.pageFrames.draws`).
async fn draws(s: &Stage) -> anyhow::Result<u64> {
    s.eval("agentDebug.pageFrames.draws")
        .await?
        .as_u64()
        .context("agentDebug.pageFrames.draws")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hidden_tab_draws_nothing_even_when_told_to_move_and_draws_again_when_shown()
-> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    let s = Stage::open("default", WEBGL).await?;
    // Another tab in front hides the page; it keeps streaming, but draws nothing, whatever it is told.
    let front = s.browser.open("about:blank").await?;
    s.wait("document.visibilityState === 'hidden'", 10).await?;
    // A frame already asked for may still land: count from a moment later.
    tokio::time::sleep(Duration::from_millis(500)).await;
    let hidden_at = draws(&s).await?;
    for x in [0.9, 0.1, 0.9, 0.1] {
        s.command(json!({"cmd": "blink", "close_ms": 60, "hold_ms": 40, "open_ms": 100}))
            .await?;
        s.command(json!({"cmd": "gaze", "x": x, "y": 0.5})).await?;
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
    let still = draws(&s).await?;
    let sent = s.eval("agentDebug.sent.audio").await?;
    assert_eq!(
        still,
        hidden_at,
        "a hidden tab drew {} times in 2 s of commands",
        still - hidden_at
    );
    ensure!(
        sent.as_u64().unwrap_or(0) > 0,
        "the hidden page stopped streaming"
    );
    // Shown again, it draws the pose it was told meanwhile.
    s.browser.close(&front).await?;
    s.wait("document.visibilityState === 'visible'", 10).await?;
    s.wait(&format!("agentDebug.pageFrames.draws > {still}"), 10)
        .await?;
    s.wait("agentDebug.eyeOffset.x > 0.6", 5).await?;
    s.quit().await;
    Ok(())
}

/// What the 3D page drew last: its model, whether it took its WebGL for software, and its triangles.
async fn drawn(s: &Stage) -> anyhow::Result<(String, Option<bool>, u64)> {
    let q = s.eval("agentDebug.avatarQuality").await?;
    Ok((
        q["model"].as_str().unwrap_or_default().to_owned(),
        q["software"].as_bool(),
        q["triangles"].as_u64().unwrap_or(0),
    ))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn software_webgl_draws_the_lite_model_and_gpu_settings_the_full_one() -> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    let s = Stage::open("3d", WEBGL).await?;
    let (model, software, lite_triangles) = drawn(&s).await?;
    s.quit().await;
    assert_eq!(model, "assets/avatar-lite.glb");
    assert_eq!(
        software,
        Some(true),
        "headless Chromium's WebGL is SwiftShader"
    );
    let s = Stage::open("3d-full", WEBGL).await?;
    let (model, software, full_triangles) = drawn(&s).await?;
    s.quit().await;
    assert_eq!(model, "assets/avatar.glb");
    assert_eq!(software, Some(false));
    assert!(
        lite_triangles > 0 && lite_triangles * 5 <= full_triangles * 2,
        "the lite head drew {lite_triangles} triangles, the full one {full_triangles}"
    );
    Ok(())
}

/// The poses both renderers are shot in, in the side-by-side sheet's order: `artifacts/avatar-<r>-<pose>.png`.
const POSES: &[&str] = &[
    "rest",
    "smile",
    "thinking",
    "listening",
    "surprise",
    "viseme-aa",
    "viseme-O",
    "viseme-FF",
    "viseme-PP",
    "viseme-SS",
    "blink",
    "look-left",
    "look-right",
];

/// Screenshots of `renderer` in every pose of `POSES` (the 3D head also from three-quarters), as
/// `artifacts/avatar-<r>-*.png`.
///
/// The 3D head is shot with the settings it has on a GPU (`avatarquality=full`); on SwiftShader it would lower its
/// resolution to keep its frame rate, which says nothing about how the model looks.
async fn screenshots(renderer: &str) -> anyhow::Result<()> {
    let s = Stage::open(
        if renderer == "3d" {
            "3d-full"
        } else {
            renderer
        },
        WEBGL,
    )
    .await?;
    ensure!(s.eval("agentDebug.avatarRenderer").await? == json!(renderer));
    let name = |what: &str| format!("avatar-{renderer}-{what}");
    // The server owns blinking from here, so no page blink spoils a shot.
    s.command(json!({"cmd": "blink", "close_ms": 10, "hold_ms": 0, "open_ms": 10}))
        .await?;
    tokio::time::sleep(Duration::from_millis(800)).await;
    s.shot(&name("rest")).await?;

    // Expressions: each mood blends in within half a second.
    for (what, mood) in [
        ("smile", "happy"),
        ("thinking", "thinking"),
        ("listening", "listening"),
        ("surprise", "surprised"),
    ] {
        s.command(json!({"cmd": "mood", "mood": mood})).await?;
        s.wait(&format!("agentDebug.mood === '{mood}'"), 5).await?;
        tokio::time::sleep(Duration::from_millis(900)).await;
        s.shot(&name(what)).await?;
    }
    s.command(json!({"cmd": "mood", "mood": "neutral"})).await?;
    s.wait("agentDebug.mood === 'neutral'", 5).await?;
    tokio::time::sleep(Duration::from_millis(900)).await;

    let visemes = ["aa", "O", "FF", "PP", "SS"];
    let mut cues = vec![json!({"t_ms": 0, "v": "sil"})];
    for (i, v) in visemes.iter().enumerate() {
        cues.push(json!({"t_ms": 200 + 4000 * i, "v": v}));
    }
    cues.push(json!({"t_ms": 200 + 4000 * visemes.len(), "v": "sil"}));
    s.speak(3, Value::Array(cues), 0.6 + 4.0 * visemes.len() as f64)
        .await?;
    for v in visemes {
        s.wait(&format!("agentDebug.viseme === '{v}'"), 15).await?;
        // Past the blend; a screenshot can take a second or two on SwiftShader, the cue lasts 4 s.
        tokio::time::sleep(Duration::from_millis(300)).await;
        s.shot(&name(&format!("viseme-{v}"))).await?;
    }
    s.wait("agentDebug.viseme === 'sil' && agentDebug.jaw < 0.05", 15)
        .await?;

    // The page holds a blink for 2 s at most, and a software-rendered frame and its capture can take longer than
    // that on a busy machine: while the shot is taken, the lids are closed again every 500 ms (a blink with no
    // closing phase starts closed, so they never open in between). The shot counts only if they are still closed
    // once it is taken (else once more).
    let closed_blink = json!({"cmd": "blink", "close_ms": 0, "hold_ms": 2000, "open_ms": 100});
    let blink_shot = name("blink");
    let mut closed = false;
    for _ in 0..4 {
        s.command(closed_blink.clone()).await?;
        s.wait("agentDebug.eyelid < 0.05", 5).await?;
        let keep_closed = async {
            loop {
                tokio::time::sleep(Duration::from_millis(500)).await;
                if let Err(e) = s.command(closed_blink.clone()).await {
                    return e;
                }
            }
        };
        tokio::select! {
            shot = s.shot(&blink_shot) => shot?,
            e = keep_closed => return Err(e),
        }
        if s.eval("agentDebug.eyelid < 0.05").await? == json!(true) {
            closed = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
    ensure!(closed, "no screenshot caught the lids closed");
    s.wait("agentDebug.eyelid > 0.9", 5).await?;

    for (what, x, check) in [
        ("look-left", 0.95, "agentDebug.eyeOffset.x < -0.6"),
        ("look-right", 0.05, "agentDebug.eyeOffset.x > 0.6"),
    ] {
        s.command(json!({"cmd": "gaze", "x": x, "y": 0.45})).await?;
        s.wait(check, 5).await?;
        // Let the head follow the eyes (its time constant is about 0.4 s).
        tokio::time::sleep(Duration::from_millis(1400)).await;
        s.shot(&name(what)).await?;
    }

    if renderer == "3d" {
        // The same head seen from three-quarters (the camera turned 35 degrees round it), in a tab of its own.
        let url = page(&s._agent, "3d-full-3q");
        let tab = s.browser.open(&url).await?;
        s.browser
            .wait_for(
                &tab,
                "window.agentDebug && agentDebug.avatarRenderer === '3d' && agentDebug.avatarFrameMs.length > 40",
                Duration::from_secs(60),
            )
            .await?;
        let png = s.browser.screenshot_of(&tab, ".stage").await?;
        ensure!(
            png.len() > 5_000,
            "the three-quarter screenshot is only {} bytes",
            png.len()
        );
        let path = agent_tests::artifacts_dir().join(format!("{}.png", name("three-quarter")));
        std::fs::write(&path, &png).with_context(|| format!("writing {}", path.display()))?;
        println!("screenshot: {}", path.display());
        s.browser.close(&tab).await?;
    }
    s.quit().await;
    Ok(())
}

/// `artifacts/avatar-side-by-side.png`: every pose of `POSES` with the 2D face above the 3D head, five poses to a
/// row in `POSES`' order, put together by ffmpeg from the two renderers' screenshots.
fn side_by_side_sheet() -> anyhow::Result<PathBuf> {
    const W: usize = 400;
    const H: usize = 274; // the stage's aspect (972 x 663)
    const COLUMNS: usize = 5;
    let dir = agent_tests::artifacts_dir();
    let mut args: Vec<String> = vec!["-y".into(), "-loglevel".into(), "error".into()];
    for pose in POSES {
        for renderer in ["2d", "3d"] {
            args.push("-i".into());
            args.push(
                dir.join(format!("avatar-{renderer}-{pose}.png"))
                    .display()
                    .to_string(),
            );
        }
    }
    // Each picture labelled with its pose and renderer where the usual font is installed (Debian's fonts-dejavu,
    // which chromium brings); without it the sheet has the same layout, unlabelled.
    let font = Path::new("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf");
    let label = |text: String| {
        if font.is_file() {
            format!(
                ",drawtext=fontfile={}:text='{text}':x=8:y=6:fontsize=15:fontcolor=white@0.85",
                font.display()
            )
        } else {
            String::new()
        }
    };
    let mut filter = String::new();
    let mut layout = Vec::new();
    for (k, pose) in POSES.iter().enumerate() {
        filter.push_str(&format!(
            "[{}:v]scale={W}:{H}{}[a{k}];[{}:v]scale={W}:{H}{}[b{k}];[a{k}][b{k}]vstack[p{k}];",
            2 * k,
            label(format!("{pose}  2D")),
            2 * k + 1,
            label(format!("{pose}  3D")),
        ));
        layout.push(format!("{}_{}", (k % COLUMNS) * W, (k / COLUMNS) * 2 * H));
    }
    for k in 0..POSES.len() {
        filter.push_str(&format!("[p{k}]"));
    }
    filter.push_str(&format!(
        "xstack=inputs={}:layout={}:fill=0x0d1117",
        POSES.len(),
        layout.join("|")
    ));
    let out = dir.join("avatar-side-by-side.png");
    args.extend([
        "-filter_complex".into(),
        filter,
        "-frames:v".into(),
        "1".into(),
        out.display().to_string(),
    ]);
    let status = std::process::Command::new("ffmpeg")
        .args(&args)
        .status()
        .context("running ffmpeg")?;
    ensure!(
        status.success(),
        "ffmpeg could not make the sheet: {status}"
    );
    Ok(out)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn screenshots_of_both_renderers_and_a_side_by_side_sheet_are_saved_as_artifacts()
-> anyhow::Result<()> {
    let _one = ONE_BROWSER.lock().await;
    screenshots("2d").await?;
    screenshots("3d").await?;
    let sheet = side_by_side_sheet()?;
    let size = std::fs::metadata(&sheet)?.len();
    ensure!(
        size > 100_000,
        "the sheet {} is only {size} bytes",
        sheet.display()
    );
    println!("side by side: {}", sheet.display());
    Ok(())
}

#[test]
fn the_committed_model_is_what_the_generator_makes_and_the_javascript_unit_tests_pass()
-> anyhow::Result<()> {
    // node --test runs the generator's and the page's pure-module tests (scripts/avatar-gen/tests), including
    // the check that regenerating assets/avatar.glb gives the committed bytes (web/js/package.json tells Node
    // that the page's .js files are ES modules).
    let out = std::process::Command::new("node")
        .args(["--test", "scripts/avatar-gen/tests/"])
        .current_dir(repo_root())
        .output()
        .context("running node (apt-get install nodejs)")?;
    let text = String::from_utf8_lossy(&out.stdout);
    ensure!(
        out.status.success(),
        "node --test failed:\n{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    ensure!(text.contains("# fail 0"), "node --test output:\n{text}");
    Ok(())
}
