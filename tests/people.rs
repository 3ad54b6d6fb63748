//! People, not boxes (issue 50), through real robot-agent processes: the vision module's per-face analysis on
//! camera frames a test satellite publishes on `Agent.video`. Two people taking turns to talk turn the avatar's
//! gaze to whoever talks; a face turned away is not greeted until it looks; "my name is ..." stores the face in the
//! pair database, a restarted agent greets that face by name and another face without one, "forget me" erases the
//! entry, and nothing is stored unless asked; a missing model stops the agent at start.
//!
//! Build the binaries first: `cargo build -p robot-agent` (`make test` does).

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use agent_contract::acquaintance::{self, AcquaintanceRecord, KEY_PREFIX};
use agent_contract::channels as ch;
use agent_contract::detections::DetectionsMsg;
use agent_tests::fixtures::fixtures;
use agent_tests::{Agent, DataDir, PATIENCE, next_json, until_subscribed, until_subscribers};
use anyhow::Context;
use flow::{Client, Publisher, Subscription};
use vision_evaluation::evaluation::{
    FRAME_US, Placement, appearing_face, face_patch, motion_frame, paste_face, read_colour,
};
use vision_evaluation::fixtures::{FaceTruth, GroundTruth};
use vision_evaluation::talking::{Side, talking_pair};

const VIDEO_HEADER: &str =
    r#"{"format":"jpeg","width":640,"height":360,"fps":15,"source":"people-test"}"#;

/// A camera that publishes its picture at 15 frames a second until it is dropped.
struct Camera {
    picture: Arc<Mutex<Vec<u8>>>,
    task: tokio::task::JoinHandle<()>,
}

impl Camera {
    async fn start(client: &Client, picture: Vec<u8>) -> anyhow::Result<Camera> {
        let video = client.publisher(ch::VIDEO.name, VIDEO_HEADER).await?;
        until_subscribed(&video).await?;
        let picture = Arc::new(Mutex::new(picture));
        let shown = picture.clone();
        let task = tokio::spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_micros(FRAME_US));
            loop {
                tick.tick().await;
                let frame = shown.lock().unwrap_or_else(PoisonError::into_inner).clone();
                if video.publish(frame).await.is_err() {
                    return;
                }
            }
        });
        Ok(Camera { picture, task })
    }

    /// From now on the camera shows `picture`.
    fn show(&self, picture: Vec<u8>) {
        *self.picture.lock().unwrap_or_else(PoisonError::into_inner) = picture;
    }
}

impl Drop for Camera {
    fn drop(&mut self) {
        self.task.abort();
    }
}

#[tokio::test]
async fn two_people_taking_turns_turn_the_gaze_to_whoever_talks() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let config = "[modules.brain]\nenabled = false\n[modules.tts]\nenabled = false\n";
    let agent = Agent::start_configured(&dir, config, "vision: watching").await?;
    let client = agent.client("people-test").await?;
    let detections = client.subscribe(ch::DETECTIONS.name).await?;
    // The voice activity the whisper satellites' relay publishes.
    let transcript = client
        .publisher(ch::TRANSCRIPT.name, r#"{"format":"json"}"#)
        .await?;
    until_subscribed(&transcript).await?;
    let turn_frames = 45;
    let clip = talking_pair(
        &fixtures(),
        &[Some(Side::Left), Some(Side::Right), Some(Side::Left)],
        turn_frames,
    )?;
    let video = client.publisher(ch::VIDEO.name, VIDEO_HEADER).await?;
    until_subscribed(&video).await?;
    transcript.publish(br#"{"vad":"start"}"#.to_vec()).await?;
    // Per turn: was the speaker named on the talking side, and did the gaze reach that side, in the frames the
    // module processed during the turn?
    let mut seen = [(false, false); 3];
    let mut tick = tokio::time::interval(Duration::from_micros(FRAME_US));
    // The clip, then its last turn again until the module has caught up with it (a busy machine processes fewer
    // frames, later), within an overall deadline; later frames count to the last turn.
    let last_turn = &clip[2 * turn_frames..];
    let deadline = tokio::time::Instant::now() + PATIENCE;
    for frame in clip.iter().chain(last_turn.iter().cycle()) {
        if seen[2] == (true, true) || tokio::time::Instant::now() > deadline {
            break;
        }
        tick.tick().await;
        video.publish(frame.jpeg.clone()).await?;
        while let Some(data) = detections.try_recv() {
            let d: DetectionsMsg = serde_json::from_slice(&data.payload)?;
            let turn = ((d.frame.seq as usize).saturating_sub(1) / turn_frames).min(2);
            let Some(side) = clip[turn * turn_frames].speaker else {
                continue;
            };
            let on_side = |x: f32| (x < 320.0) == (side == Side::Left);
            let speaker = d
                .people
                .iter()
                .flatten()
                .find(|p| p.speaking)
                .map(|p| p.face.x as f32 + p.face.w as f32 / 2.0);
            if speaker.is_some_and(on_side) {
                seen[turn].0 = true;
            }
            if d.gaze
                .as_ref()
                .is_some_and(|g| g.source == "face" && on_side(g.x * 640.0))
            {
                seen[turn].1 = true;
            }
        }
    }
    transcript.publish(br#"{"vad":"end"}"#.to_vec()).await?;
    assert_eq!(
        seen,
        [(true, true); 3],
        "per turn (left, right, left): (the talking side named the speaker, the gaze on it)"
    );
    Ok(())
}

/// A colour camera frame of the empty room with one face pasted in: the portrait of the appearing-face trials
/// (`known`), or a woman from another photo.
fn one_face(known: bool) -> anyhow::Result<Vec<u8>> {
    if known {
        pasted(&appearing_face(&fixtures())?)
    } else {
        fixture_face("faces/dlib_2008_001009.jpg", 0)
    }
}

/// Face `index` of an annotated fixture photo, pasted into the empty room.
fn fixture_face(image: &str, index: usize) -> anyhow::Result<Vec<u8>> {
    let dir = fixtures();
    let truth = GroundTruth::load(&dir)?;
    let photo = truth
        .faces
        .iter()
        .find(|t| t.image == image)
        .with_context(|| format!("the fixture photo {image}"))?;
    let face = FaceTruth {
        image: photo.image.clone(),
        face_count: 1,
        boxes: vec![*photo.boxes.get(index).context("no such face")?],
    };
    pasted(&face_patch(&dir, &face)?)
}

fn pasted(patch: &vision_evaluation::evaluation::FacePatch) -> anyhow::Result<Vec<u8>> {
    let room = read_colour(&motion_frame(&fixtures(), 1))?;
    let (jpeg, _) = paste_face(
        &room,
        patch,
        Placement {
            face_px: 120,
            centre_x: 320,
            centre_y: 170,
        },
    )?;
    Ok(jpeg)
}

/// The captions of what the agent says, in order.
async fn next_caption(avatar: &Subscription) -> anyhow::Result<String> {
    let command = next_json(avatar, PATIENCE, |c| c["cmd"] == "say").await?;
    command["text"]
        .as_str()
        .map(str::to_owned)
        .context("a caption without text")
}

/// A robot-agent on the default program, speaking with espeak-ng (quick to start), hearing a test satellite.
struct Scene {
    agent: Agent,
    client: Client,
    transcript: Publisher,
    avatar: Subscription,
}

impl Scene {
    async fn start(dir: &DataDir) -> anyhow::Result<Scene> {
        let config = "[modules.tts]\nengine = \"espeak\"\n";
        let agent = Agent::start_configured(dir, config, "vision: watching").await?;
        let client = agent.client("people-test").await?;
        let avatar = client.subscribe(ch::AVATAR.name).await?;
        let transcript = client
            .publisher(ch::TRANSCRIPT.name, r#"{"format":"json"}"#)
            .await?;
        // The brain, the TTS module, the observer and the vision module follow transcripts.
        until_subscribers(&client, ch::TRANSCRIPT.name, 4, PATIENCE).await?;
        Ok(Scene {
            agent,
            client,
            transcript,
            avatar,
        })
    }

    /// Stops the agent cleanly, so that the next one opens the same pair database.
    async fn stop(mut self) -> anyhow::Result<()> {
        self.agent.terminate()?;
        self.agent.wait_exit(PATIENCE).await?;
        Ok(())
    }

    async fn hear(&self, text: &str) -> anyhow::Result<()> {
        let message = serde_json::json!({ "text": text, "final": true }).to_string();
        self.transcript.publish(message.into_bytes()).await?;
        Ok(())
    }

    async fn stored(&self) -> anyhow::Result<Vec<String>> {
        Ok(self
            .client
            .var_list()
            .await?
            .into_iter()
            .filter(|k| k.starts_with(KEY_PREFIX))
            .collect())
    }
}

#[tokio::test]
async fn a_face_introduced_by_name_is_greeted_by_it_after_a_restart_and_forgotten_on_request()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let anna = one_face(true)?;
    let stranger = one_face(false)?;

    // First visit: greeted without a name, and nothing is stored until she says her name.
    let scene = Scene::start(&dir).await?;
    let camera = Camera::start(&scene.client, anna.clone()).await?;
    let greeting = next_caption(&scene.avatar).await?;
    assert!(
        greeting.ends_with("! Nice to see you. Ask me anything."),
        "{greeting:?}"
    );
    assert_eq!(
        scene.stored().await?,
        Vec::<String>::new(),
        "stored without being asked"
    );
    scene.hear("Hello, my name is Anna.").await?;
    assert_eq!(
        next_caption(&scene.avatar).await?,
        "Nice to meet you, Anna. I will remember your face."
    );
    let record: AcquaintanceRecord = serde_json::from_value(
        scene
            .client
            .var_get(&acquaintance::key("Anna"))
            .await?
            .context("no entry for Anna in the pair database")?,
    )?;
    assert_eq!(
        (record.name.as_str(), record.descriptor.len()),
        ("Anna", 128)
    );
    drop(camera);
    scene.stop().await?;

    // The agent starts again: a stranger is greeted without a name.
    let scene = Scene::start(&dir).await?;
    let camera = Camera::start(&scene.client, stranger).await?;
    let greeting = next_caption(&scene.avatar).await?;
    assert!(
        greeting.ends_with("! Nice to see you. Ask me anything."),
        "{greeting:?}"
    );
    scene.hear("Do you know me?").await?;
    assert_eq!(
        next_caption(&scene.avatar).await?,
        "I don't know you yet. Tell me your name, and I will remember your face."
    );
    drop(camera);
    scene.stop().await?;

    // And again: Anna is greeted by name, and then forgotten when she asks.
    let scene = Scene::start(&dir).await?;
    let camera = Camera::start(&scene.client, anna).await?;
    let greeting = next_caption(&scene.avatar).await?;
    assert!(
        greeting.ends_with(", Anna! Nice to see you again."),
        "{greeting:?}"
    );
    scene.hear("Please forget me.").await?;
    assert_eq!(
        next_caption(&scene.avatar).await?,
        "All right, Anna. I have forgotten your face."
    );
    assert_eq!(
        scene.stored().await?,
        Vec::<String>::new(),
        "the entry is still there"
    );
    drop(camera);
    Ok(())
}

#[tokio::test]
async fn a_missing_face_model_stops_the_agent_at_start_naming_the_file_and_the_make_target()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let missing = dir
        .path()
        .join("nowhere/shape_predictor_68_face_landmarks.dat");
    let config = format!(
        "[modules.vision.people]\nlandmarks = {:?}\n",
        missing.display().to_string()
    );
    let started = Agent::start_configured(&dir, &config, "vision: watching").await;
    let Err(error) = started else {
        anyhow::bail!("robot-agent started without its landmark model");
    };
    let text = format!("{error:#}");
    assert!(
        text.contains(&missing.display().to_string()) && text.contains("make model-face"),
        "{text}"
    );
    Ok(())
}

#[tokio::test]
async fn a_face_turned_away_is_not_greeted_until_it_looks_at_the_agent() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let scene = Scene::start(&dir).await?;
    let detections = scene.client.subscribe(ch::DETECTIONS.name).await?;
    // A young man in a group photo, his head turned well away from the camera (yaw about 55 degrees).
    let camera = Camera::start(
        &scene.client,
        fixture_face("faces/dlib_2008_002079.jpg", 5)?,
    )
    .await?;
    // Three seconds of him: seen as a person who does not look, and not greeted.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(3);
    let mut turned_away = 0;
    while tokio::time::Instant::now() < deadline {
        let Ok(Some(data)) = tokio::time::timeout_at(deadline, detections.recv()).await else {
            break;
        };
        let d: DetectionsMsg = serde_json::from_slice(&data.payload)?;
        let people = d.people.unwrap_or_default();
        anyhow::ensure!(
            people.iter().all(|p| !p.looking),
            "a person looking: {people:?}"
        );
        turned_away += usize::from(!people.is_empty());
    }
    while let Some(data) = scene.avatar.try_recv() {
        let command: serde_json::Value = serde_json::from_slice(&data.payload)?;
        anyhow::ensure!(command["cmd"] != "say", "the agent spoke: {command}");
    }
    assert!(
        turned_away >= 5,
        "the turned face was analysed in {turned_away} frames"
    );
    // The portrait, facing the camera: now the greeting comes.
    camera.show(one_face(true)?);
    let greeting = next_caption(&scene.avatar).await?;
    assert!(
        greeting.ends_with("! Nice to see you. Ask me anything."),
        "{greeting:?}"
    );
    drop(camera);
    Ok(())
}
