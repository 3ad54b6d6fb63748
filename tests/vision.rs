//! The vision module through a real robot-agent: fixture JPEGs are published on `Agent.video` by a test
//! satellite, and the assertions read `Agent.faces`, `Agent.codes`, `Agent.motion`, `Agent.detections` and
//! `Agent.avatar` (faces: recall and false positives on the annotated photos, at stored size and letterboxed;
//! QR: exact texts, four codes on the page, one report per appearance; motion on the 15 fps sequence without
//! flicker; bad frames counted and skipped; newest-frame processing under a flood; re-subscription when the camera
//! channel comes back; a face that comes into view boxed within four processed frames).
//!
//! Build the binaries first: `cargo build -p robot-agent` (`make test` does).

use agent_contract::channels as ch;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use agent_tests::{Agent, DataDir, PATIENCE, fixture, recv_until};
use agent_vision::geometry::BoxPx;
use agent_vision::wire::{CodesMsg, DetectionsMsg, FacesMsg, GazeCommand, MotionMsg};
use anyhow::{Context, bail};
use flow::{Client, Publisher, Subscription};
use serde::de::DeserializeOwned;
use vision_evaluation::evaluation::{
    Placement, appearing_face, motion_frame, paste_face, read_colour,
};
use vision_evaluation::fixtures::{
    FaceTotals, FaceTruth, GroundTruth, image_as_jpeg, letterbox, score_faces,
};

/// The camera's frame period (15 fps).
const FRAME: Duration = Duration::from_millis(66);

const VIDEO_HEADER: &str =
    r#"{"format":"jpeg","width":640,"height":360,"fps":15,"source":"vision-test"}"#;

/// A robot-agent with the vision module and a satellite acting as the camera.
struct Rig {
    _dir: DataDir,
    agent: Agent,
    camera: Client,
    /// The camera's channel; `None` while the camera is "unplugged".
    video: Option<Publisher>,
    /// Frames published so far on the current `Agent.video` channel; equals the channel's last sequence number.
    published: u64,
}

impl Rig {
    async fn start(extra_config: &str) -> anyhow::Result<Rig> {
        let dir = DataDir::new()?;
        // Only the vision module matters here; the others would compete for the CPU.
        let config = format!(
            "[modules.brain]\nenabled = false\n[modules.tts]\nenabled = false\n[modules.vision]\n{extra_config}\n"
        );
        let agent = Agent::start_configured(&dir, &config, "vision: watching").await?;
        let camera = agent.client("vision-test").await?;
        let video = camera.publisher(ch::VIDEO.name, VIDEO_HEADER).await?;
        until_subscribed(&video).await?;
        Ok(Rig {
            _dir: dir,
            agent,
            camera,
            video: Some(video),
            published: 0,
        })
    }

    /// Publishes one frame and returns its sequence number on `Agent.video`.
    async fn publish(&mut self, jpeg: &[u8]) -> anyhow::Result<u64> {
        self.video
            .as_ref()
            .context("no camera channel")?
            .publish(jpeg.to_vec())
            .await?;
        self.published += 1;
        Ok(self.published)
    }

    /// Removes the camera channel (dropping the publisher removes it from the hub) and adds it again.
    async fn replug_camera(&mut self) -> anyhow::Result<()> {
        self.video = None;
        tokio::time::sleep(Duration::from_millis(300)).await;
        let video = self.camera.publisher(ch::VIDEO.name, VIDEO_HEADER).await?;
        until_subscribed(&video).await?;
        self.video = Some(video);
        self.published = 0;
        Ok(())
    }
}

async fn until_subscribed(publisher: &Publisher) -> anyhow::Result<()> {
    let mut watch = publisher.subscribers();
    tokio::time::timeout(PATIENCE, watch.wait_for(|has| *has))
        .await
        .context("the vision module never subscribed to Agent.video")??;
    Ok(())
}

/// The next message on `sub`, parsed; fails after [`PATIENCE`].
async fn next<T: DeserializeOwned>(sub: &Subscription) -> anyhow::Result<T> {
    let data = tokio::time::timeout(PATIENCE, sub.recv())
        .await
        .with_context(|| format!("nothing on {} within {PATIENCE:?}", sub.name()))?
        .context("subscription closed")?;
    serde_json::from_slice(&data.payload).with_context(|| format!("bad JSON on {}", sub.name()))
}

/// Messages on `sub`, parsed, until `pick` takes one; fails after `patience` in all, however many others come.
async fn next_until<T: DeserializeOwned, R>(
    sub: &Subscription,
    what: &str,
    patience: Duration,
    mut pick: impl FnMut(T) -> Option<R>,
) -> anyhow::Result<R> {
    recv_until(sub, what, patience, |data| {
        match serde_json::from_slice::<T>(&data.payload) {
            Ok(msg) => pick(msg).map(Ok),
            Err(e) => Some(Err(
                anyhow::Error::from(e).context(format!("bad JSON on {}", sub.name()))
            )),
        }
    })
    .await?
}

/// Any queued messages on `sub`, without waiting.
fn drain<T: DeserializeOwned>(sub: &Subscription) -> anyhow::Result<Vec<T>> {
    let mut out = Vec::new();
    while let Some(data) = sub.try_recv() {
        out.push(serde_json::from_slice(&data.payload)?);
    }
    Ok(out)
}

fn boxes(msg: &FacesMsg) -> Vec<BoxPx> {
    msg.faces
        .iter()
        .map(|b| BoxPx {
            x: b.x,
            y: b.y,
            width: b.w,
            height: b.h,
        })
        .collect()
}

#[tokio::test]
async fn faces_on_annotated_photos_reach_recall_with_few_false_positives() -> anyhow::Result<()> {
    let truth = GroundTruth::load(&agent_tests::fixtures::fixtures())?;
    let mut images = Vec::new();
    for image in &truth.faces {
        let path = fixture(&image.image)?;
        images.push((std::fs::read(&path)?, image.clone(), frame_size(&path)?));
    }
    let totals = faces_through_the_module(&images).await?;
    totals.check().map_err(anyhow::Error::msg)
}

/// The same photos as the camera sends them: letterboxed into 640x360 colour JPEGs at the page's quality, where
/// the faces are 0.96 of their stored size or less (the bar the cascades missed; docs/vision.md).
#[tokio::test]
async fn faces_letterboxed_as_the_camera_sends_them_meet_the_bar() -> anyhow::Result<()> {
    let dir = agent_tests::fixtures::fixtures();
    let truth = GroundTruth::load(&dir)?;
    let mut images = Vec::new();
    for image in &truth.faces {
        let camera = letterbox(&dir, image)?;
        images.push((camera.jpeg, camera.truth, (640, 360)));
    }
    let totals = faces_through_the_module(&images).await?;
    totals.check().map_err(anyhow::Error::msg)
}

/// Feeds each `(jpeg, truth, frame size)` to a real robot-agent's vision module as a camera looking at a still
/// scene, and scores the faces it publishes once a whole scan has run on the image.
async fn faces_through_the_module(
    images: &[(Vec<u8>, FaceTruth, (u32, u32))],
) -> anyhow::Result<FaceTotals> {
    let mut rig = Rig::start("").await?;
    let faces = rig.camera.subscribe(ch::FACES.name).await?;
    let mut totals = FaceTotals::default();
    println!(
        "{:<42} {:>9} {:>5} {:>3}",
        "image", "annotated", "found", "fp"
    );
    for (jpeg, image, size) in images {
        drain::<FacesMsg>(&faces)?;
        let first_seq = rig.published + 1;
        // Like a camera looking at a still scene: feed the image until a whole scan has run on it alone (the scan
        // counter has advanced twice since its first frame: the cascades spread a scan over frames, the network
        // runs every few frames).
        let mut start_cycles = None;
        let result = tokio::time::timeout(PATIENCE * 4, async {
            loop {
                rig.publish(jpeg).await?;
                tokio::time::sleep(FRAME).await;
                for msg in drain::<FacesMsg>(&faces)? {
                    if msg.frame.seq < first_seq {
                        continue;
                    }
                    let start = *start_cycles.get_or_insert(msg.scan_cycles);
                    if msg.scan_cycles >= start + 2 {
                        return anyhow::Ok(msg);
                    }
                }
            }
        })
        .await
        .with_context(|| format!("no complete face scan of {}", image.image))??;
        let score = score_faces(image, &boxes(&result), 0.3);
        println!(
            "{:<42} {:>9} {:>5} {:>3}",
            image.image, score.annotated, score.found, score.false_positives
        );
        assert_eq!((result.frame.width, result.frame.height), *size);
        totals.add(&score);
    }
    println!("{}", totals.summary());
    Ok(totals)
}

/// Width and height from the JPEG's frame header, to check the messages report frame pixels.
fn frame_size(path: &Path) -> anyhow::Result<(u32, u32)> {
    let header = agent_vision::jpeg::inspect(&std::fs::read(path)?)?;
    Ok((header.width, header.height))
}

#[tokio::test]
async fn qr_codes_decode_exactly_and_are_reported_once_per_appearance() -> anyhow::Result<()> {
    let mut rig = Rig::start("").await?;
    let codes = rig.camera.subscribe(ch::CODES.name).await?;
    let detections = rig.camera.subscribe(ch::DETECTIONS.name).await?;
    let truth = GroundTruth::load(&agent_tests::fixtures::fixtures())?;
    // A frame without codes between images, long enough (> forget_after_ms) for a code to count as gone.
    let blank = std::fs::read(fixture(
        "motion/derived/intel_one-by-one_t2-10s_640x360_15fps/frame_0001.jpg",
    )?)?;
    for image in &truth.qr {
        let jpeg = image_as_jpeg(&fixture(&image.image)?)?;
        let first_seq = rig.published + 1;
        for _ in 0..30 {
            rig.publish(&jpeg).await?;
            tokio::time::sleep(FRAME).await;
        }
        let last_seq = rig.published;
        for _ in 0..25 {
            rig.publish(&blank).await?;
            tokio::time::sleep(FRAME).await;
        }
        // Wait until the module has processed a frame past this image, so every report about it is in.
        next_until(
            &detections,
            "detections of a frame past the image",
            PATIENCE * 2,
            |msg: DetectionsMsg| (msg.frame.seq > last_seq).then_some(()),
        )
        .await?;
        let mut reported: BTreeMap<String, usize> = BTreeMap::new();
        for msg in drain::<CodesMsg>(&codes)? {
            if (first_seq..=last_seq).contains(&msg.frame.seq) {
                for code in msg.codes {
                    assert!(code.new);
                    *reported
                        .entry(code.text.context("QR text is UTF-8")?)
                        .or_default() += 1;
                }
            } else {
                bail!("codes reported for a frame without codes: {:?}", msg.frame);
            }
        }
        println!(
            "{}: {:?}",
            image.image,
            reported.values().collect::<Vec<_>>()
        );
        let mut expected: BTreeMap<String, usize> = BTreeMap::new();
        for text in &image.texts {
            *expected.entry(text.clone()).or_default() += 1;
        }
        assert_eq!(
            reported, expected,
            "{}: each code exactly once over 30 frames",
            image.image
        );
    }
    Ok(())
}

#[tokio::test]
async fn motion_sequence_is_still_then_moving_without_flicker() -> anyhow::Result<()> {
    let mut rig = Rig::start("").await?;
    let motion = rig.camera.subscribe(ch::MOTION.name).await?;
    let mut moving: BTreeMap<u64, bool> = BTreeMap::new();
    for index in 1..=120 {
        let path =
            format!("motion/derived/intel_one-by-one_t2-10s_640x360_15fps/frame_{index:04}.jpg");
        let seq = rig.publish(&std::fs::read(fixture(&path)?)?).await?;
        assert_eq!(seq, index);
        tokio::time::sleep(FRAME).await;
        for msg in drain::<MotionMsg>(&motion)? {
            moving.insert(msg.frame.seq, msg.moving);
        }
    }
    if moving.keys().next_back().is_none_or(|&last| last < 120) {
        next_until(
            &motion,
            "the motion of frame 120",
            PATIENCE * 2,
            |msg: MotionMsg| {
                moving.insert(msg.frame.seq, msg.moving);
                moving
                    .keys()
                    .next_back()
                    .is_some_and(|&last| last >= 120)
                    .then_some(())
            },
        )
        .await?;
    }
    let line: String = (1..=120)
        .map(|s| match moving.get(&s) {
            Some(true) => 'M',
            Some(false) => '.',
            None => ' ',
        })
        .collect();
    println!("frames 1-120 (blank = skipped by the module): {line}");
    assert!(
        moving.range(..=60).all(|(_, m)| !m),
        "motion in the empty scene: {line}"
    );
    assert!(
        moving.range(61..=63).any(|(_, m)| *m),
        "the person entering at frame 61 was not seen: {line}"
    );
    assert!(
        moving.range(62..=95).all(|(_, m)| *m),
        "motion flickered off while the person walks: {line}"
    );
    Ok(())
}

#[tokio::test]
async fn bad_frames_are_counted_and_skipped() -> anyhow::Result<()> {
    let mut rig = Rig::start("").await?;
    let detections = rig.camera.subscribe(ch::DETECTIONS.name).await?;
    let good = std::fs::read(fixture("faces/derived/fr_two_people_640x360.jpg")?)?;
    rig.publish(b"this is not a JPEG").await?;
    tokio::time::sleep(FRAME).await;
    rig.publish(&good[..good.len() / 2]).await?;
    tokio::time::sleep(FRAME).await;
    let good_seq = rig.publish(&good).await?;
    let msg: DetectionsMsg = next(&detections).await?;
    assert_eq!(
        msg.frame.seq, good_seq,
        "only the good frame yields detections"
    );
    assert_eq!(msg.counters.context("no counters")?.bad, 2);
    rig.agent
        .output
        .wait_for("skipped a bad frame", 2, PATIENCE)
        .await?;
    assert_eq!(
        rig.agent.output.matching("truncated JPEG").len(),
        1,
        "the log names the reason"
    );
    Ok(())
}

#[tokio::test]
async fn a_flood_of_frames_is_skipped_not_queued() -> anyhow::Result<()> {
    let mut rig = Rig::start("").await?;
    let detections = rig.camera.subscribe(ch::DETECTIONS.name).await?;
    let frame = std::fs::read(fixture("faces/derived/fr_two_people_640x360.jpg")?)?;
    for _ in 0..300 {
        rig.publish(&frame).await?;
    }
    // The newest frame is always processed eventually; most of the flood is skipped on the way.
    let newest = rig.published;
    let last = next_until(
        &detections,
        "detections of the newest frame",
        PATIENCE * 2,
        |msg: DetectionsMsg| (msg.frame.seq == newest).then_some(msg),
    )
    .await?;
    let counters = last.counters.context("no counters")?;
    println!(
        "processed {} skipped {} of 300",
        counters.processed, counters.skipped
    );
    assert!(counters.processed < 300, "{counters:?}");
    assert!(counters.skipped > 0, "{counters:?}");
    Ok(())
}

#[tokio::test]
async fn detections_resume_when_the_camera_channel_comes_back_and_gaze_follows_a_face()
-> anyhow::Result<()> {
    let mut rig = Rig::start("avatar_gaze = true").await?;
    let detections = rig.camera.subscribe(ch::DETECTIONS.name).await?;
    let avatar = rig.camera.subscribe(ch::AVATAR.name).await?;
    let frame = std::fs::read(fixture("faces/derived/fr_two_people_640x360.jpg")?)?;
    rig.publish(&frame).await?;
    let first: DetectionsMsg = next(&detections).await?;
    assert_eq!(first.frame.seq, 1);

    // The camera goes away (its channel is removed) and a new one appears under the same name.
    rig.replug_camera().await?;
    let mut gaze_on_face = None;
    let outcome = tokio::time::timeout(PATIENCE * 2, async {
        loop {
            rig.publish(&frame).await?;
            tokio::time::sleep(FRAME).await;
            for command in drain::<GazeCommand>(&avatar)? {
                if command.cmd == "gaze" && command.source == "face" {
                    gaze_on_face = Some(command);
                }
            }
            let resumed = drain::<DetectionsMsg>(&detections)?;
            if gaze_on_face.is_some() && !resumed.is_empty() {
                return anyhow::Ok(resumed);
            }
        }
    })
    .await
    .context("no detections and face gaze after the camera channel came back")??;
    assert!(
        outcome.iter().any(|m| m.frame.seq <= rig.published),
        "frames of the new channel are processed"
    );
    let gaze = gaze_on_face.context("gaze")?;
    assert!(
        (0.0..=1.0).contains(&gaze.x) && (0.0..=1.0).contains(&gaze.y),
        "{gaze:?}"
    );
    Ok(())
}

/// A face that comes into an empty room is boxed on `Agent.detections` within four of the frames the module
/// processes after it appears (the issue's 300 ms is 4.5 frames at 15 fps): the module scans where motion appears
/// first. The smallest face the scan looks for, in the middle of the frame, is the hard case (it once waited 19
/// frames for the scan cycle). Counted in processed frames, so a busy machine that makes the module skip frames
/// does not fail it.
#[tokio::test]
async fn a_face_that_comes_into_view_is_boxed_within_four_processed_frames() -> anyhow::Result<()> {
    let mut rig = Rig::start("").await?;
    let detections = rig.camera.subscribe(ch::DETECTIONS.name).await?;
    let dir = agent_tests::fixtures::fixtures();
    let patch = appearing_face(&dir)?;
    let room: Vec<std::path::PathBuf> = (1..=20).map(|i| motion_frame(&dir, i)).collect();
    let last_room = room.last().context("no room frames")?;
    let still = read_colour(last_room)?;
    for placement in [
        Placement {
            face_px: 32,
            centre_x: 320,
            centre_y: 200,
        },
        Placement {
            face_px: 90,
            centre_x: 150,
            centre_y: 110,
        },
    ] {
        // The empty room, as the camera sends it, so that the face's arrival is motion.
        for frame in &room {
            rig.publish(&std::fs::read(frame)?).await?;
            tokio::time::sleep(FRAME).await;
        }
        let (jpeg, face) = paste_face(&still, &patch, placement)?;
        let first = rig.published + 1;
        let mut processed = 0;
        let boxed_after = tokio::time::timeout(PATIENCE * 2, async {
            loop {
                rig.publish(&jpeg).await?;
                tokio::time::sleep(FRAME).await;
                for msg in drain::<DetectionsMsg>(&detections)? {
                    if msg.frame.seq < first {
                        continue;
                    }
                    processed += 1;
                    let hit = msg.faces.iter().flatten().any(|b| {
                        let found = BoxPx {
                            x: b.x,
                            y: b.y,
                            width: b.w,
                            height: b.h,
                        };
                        found.iou(&face) >= 0.3
                    });
                    if hit || processed > 4 {
                        return anyhow::Ok((hit, processed));
                    }
                }
            }
        })
        .await
        .with_context(|| format!("{placement:?}: no detections"))??;
        println!("{placement:?}: {boxed_after:?} (boxed, processed frames)");
        assert!(
            boxed_after.0,
            "{placement:?}: no box within 4 processed frames"
        );
    }
    Ok(())
}
