//! The vision module (`[modules.vision]`): runs the `agent-vision` detectors on the camera channel and publishes
//! what they find on `Agent.faces`, `Agent.motion`, `Agent.codes` and `Agent.detections` (and optionally a `gaze`
//! command on `Agent.avatar`). See docs/vision.md for the messages.
//!
//! Frames are never queued for the detectors: while one frame is being processed on the detectors' own thread (at
//! background priority, `vision_worker.rs`), newer
//! frames replace older ones in the subscription's drop-oldest queue, and the next round takes only the newest,
//! counting the rest as skipped. The subscription is sticky, so when the camera channel disappears and comes back
//! (a browser reconnects, a test publishes again) frames flow again by themselves; a sequence number that starts
//! over resets the detectors' memory of the old stream.

use std::collections::VecDeque;

use agent_vision::pipeline::FaceDetection;
use agent_vision::settings::VisionSettings;
use agent_vision::wire::{self, CountersMsg};
use agent_vision::{FrameDetections, ProcessError};
use anyhow::Context;
use bytes::Bytes;
use flow::Publisher;
use flow::tick::Tick;
use serde::Serialize;
use tracing::{debug, info, warn};

use flow_hub::module::{Module, ModuleContext, ModuleFuture};

use super::acquaintances::Acquaintances;
use super::vision_worker::VisionWorker;

use agent_contract::channels::{
    self, ACQUAINTANCES, AVATAR, CODES, DETECTIONS, FACES, MOTION, TRANSCRIPT,
};
use agent_contract::transcript::Heard;

/// How many recent frame times the status report summarises.
const RECENT_FRAMES: usize = 64;

/// The built-in vision module.
#[derive(Debug, Default)]
pub struct VisionModule;

impl Module for VisionModule {
    fn name(&self) -> &'static str {
        "vision"
    }

    fn check(&self, params: &serde_json::Value) -> anyhow::Result<()> {
        let settings = VisionSettings::from_json(params).context("[modules.vision]")?;
        let pipeline = settings.pipeline_params().context("[modules.vision]")?;
        // The network's file is checked here too, so that a missing model stops the server at start with the key
        // named, before any module runs.
        if let Some(FaceDetection::CenterFace(net)) = &pipeline.faces {
            net.check_model().context("[modules.vision]")?;
        }
        if let Some(people) = &pipeline.people {
            people
                .models
                .check()
                .context("[modules.vision] people (the per-face analysis; people.enabled = false turns it off)")?;
        }
        Ok(())
    }

    fn run(self: Box<Self>, ctx: ModuleContext) -> ModuleFuture {
        Box::pin(run(ctx))
    }
}

/// The module's output channels.
struct Outputs {
    faces: Publisher,
    motion: Publisher,
    codes: Publisher,
    detections: Publisher,
    avatar: Option<Publisher>,
}

/// Counters and recent frame times for `/api/status` and `Agent.detections`.
#[derive(Debug, Default)]
struct Figures {
    counters: CountersMsg,
    dropped_by_queue: u64,
    recent_ms: VecDeque<f64>,
    last_seq: Option<u64>,
    stream_restarts: u64,
}

async fn run(mut ctx: ModuleContext) -> anyhow::Result<()> {
    let settings = VisionSettings::from_json(&ctx.params).context("[modules.vision]")?;
    let params = settings.pipeline_params().context("[modules.vision]")?;
    let people = params.people.clone();
    agent_vision::set_opencv_threads(settings.threads).context("[modules.vision] threads")?;
    // The detectors run on their own thread at background priority (vision_worker.rs), so that on a busy machine
    // the spoken turn goes first.
    let pipeline = VisionWorker::start(params).await?;

    let client = ctx.client.clone();
    let outputs = Outputs {
        faces: client
            .publisher(FACES.name, &channels::headers::vision("faces"))
            .await?,
        motion: client
            .publisher(MOTION.name, &channels::headers::vision("motion"))
            .await?,
        codes: client
            .publisher(CODES.name, &channels::headers::vision("codes"))
            .await?,
        detections: client
            .publisher(DETECTIONS.name, &channels::headers::vision("detections"))
            .await?,
        avatar: if settings.avatar_gaze {
            match client
                .publisher(
                    AVATAR.name,
                    r#"{"format":"json","commands":["gaze"],"source":"vision"}"#,
                )
                .await
            {
                Ok(publisher) => Some(publisher),
                Err(e) => {
                    warn!(
                        "vision: not publishing gaze on {} ({e}); it stays in {}",
                        AVATAR.name, DETECTIONS.name
                    );
                    None
                }
            }
        } else {
            None
        },
    };
    let source = client.subscribe(&settings.source).await?;
    info!(source = %settings.source, "vision: watching {} for faces, motion and codes", settings.source);
    // The per-face analysis hears the voice activity (who is talking is the face whose mouth moves while a voice
    // is heard) and answers for the acquaintances.
    let (transcripts, mut acquaintances, mut service) = match &people {
        Some(people) => {
            let known = Acquaintances::load(&client, people.match_distance).await;
            pipeline.people().set_known(known.known().to_vec());
            let service = if people.models.descriptor.is_some() {
                Some(
                    client
                        .serve(ACQUAINTANCES.name, channels::headers::ACQUAINTANCES)
                        .await?,
                )
            } else {
                None
            };
            (
                Some(client.subscribe(TRANSCRIPT.name).await?),
                Some(known),
                service,
            )
        }
        None => (None, None, None),
    };

    let mut figures = Figures::default();
    let mut ticks = ctx.ticks();
    loop {
        tokio::select! {
            () = ctx.stopped() => break,
            latest = source.recv_latest() => {
                let Some((frame, skipped)) = latest else { break };
                figures.counters.skipped += skipped as u64;
                figures.dropped_by_queue = source.dropped();
                if figures.last_seq.is_some_and(|last| frame.seq <= last) {
                    // The channel was removed and added again: a new stream starts at sequence 1.
                    figures.stream_restarts += 1;
                    pipeline.reset_stream();
                    debug!(seq = frame.seq, "vision: source stream restarted");
                }
                figures.last_seq = Some(frame.seq);
                let result = pipeline.process(frame.payload, frame.seq, frame.ts_us).await?;
                match result {
                    Ok(detections) => {
                        figures.counters.processed += 1;
                        if figures.recent_ms.len() == RECENT_FRAMES {
                            figures.recent_ms.pop_front();
                        }
                        figures.recent_ms.push_back(detections.timings.total.as_secs_f64() * 1000.0);
                        publish(&outputs, &detections, figures.counters).await;
                    }
                    Err(ProcessError::Frame(reason)) => {
                        figures.counters.bad += 1;
                        // Every bad frame is counted; the log shows the first ones and then every hundredth.
                        if figures.counters.bad <= 10 || figures.counters.bad % 100 == 0 {
                            warn!(bad_frames = figures.counters.bad, "vision: skipped a bad frame on {}: {reason}", settings.source);
                        }
                    }
                    Err(ProcessError::Detector(e)) => return Err(e).context("vision detector failed"),
                }
            }
            heard = next_voice(transcripts.as_ref()) => {
                match heard {
                    Some(Voice::Start) => pipeline.people().set_voice(true),
                    Some(Voice::End) => pipeline.people().set_voice(false),
                    Some(Voice::Other) => {}
                    None => break,
                }
            }
            call = next_call(service.as_mut()) => {
                let Some(call) = call else { break };
                let answer = match acquaintances.as_mut() {
                    Some(known) => known.handle(&client, pipeline.people(), &call.payload).await,
                    None => Err("the per-face analysis is off".to_owned()),
                };
                if let Err(reason) = &answer {
                    info!("vision: {} refused: {reason}", ACQUAINTANCES.name);
                }
                if let Err(e) = call.respond(answer).await {
                    debug!("vision: answer on {} not delivered: {e}", ACQUAINTANCES.name);
                }
            }
            tick = ticks.recv() => {
                if matches!(tick, Ok(Tick::OneSec)) {
                    let mut report = status(&figures);
                    report["acquaintances"] = serde_json::json!(acquaintances.as_ref().map(|a| a.known().len()));
                    ctx.report(report);
                }
            }
        }
    }
    Ok(())
}

/// What a transcript message says of the voice.
enum Voice {
    Start,
    End,
    Other,
}

/// The next voice event, or never when the analysis is off; `None` when the subscription ended.
async fn next_voice(transcripts: Option<&flow::Subscription>) -> Option<Voice> {
    let Some(transcripts) = transcripts else {
        return std::future::pending().await;
    };
    let data = transcripts.recv().await?;
    Some(match serde_json::from_slice::<Heard>(&data.payload) {
        Ok(heard) => match heard.vad.as_deref() {
            Some("start") => Voice::Start,
            Some("end") => Voice::End,
            _ => Voice::Other,
        },
        Err(_) => Voice::Other,
    })
}

/// The next call on `Agent.acquaintances`, or never when the module does not serve it.
async fn next_call(service: Option<&mut flow::Service>) -> Option<flow::ServiceCall> {
    match service {
        Some(service) => service.next().await,
        None => std::future::pending().await,
    }
}

async fn publish(outputs: &Outputs, detections: &FrameDetections, counters: CountersMsg) {
    if let Some(faces) = wire::faces_msg(detections) {
        send(&outputs.faces, &faces).await;
    }
    if let Some(motion) = wire::motion_msg(detections) {
        send(&outputs.motion, &motion).await;
    }
    if let Some(codes) = wire::codes_msg(detections) {
        send(&outputs.codes, &codes).await;
    }
    send(
        &outputs.detections,
        &wire::detections_msg(detections, counters),
    )
    .await;
    if let Some(avatar) = &outputs.avatar {
        send(avatar, &wire::gaze_command(detections)).await;
    }
}

async fn send<T: Serialize>(publisher: &Publisher, message: &T) {
    match serde_json::to_vec(message) {
        Ok(json) => {
            if let Err(e) = publisher.publish(Bytes::from(json)).await {
                debug!("vision: publishing on {} failed: {e}", publisher.name());
            }
        }
        Err(e) => warn!(
            "vision: cannot encode a message for {}: {e}",
            publisher.name()
        ),
    }
}

fn status(figures: &Figures) -> serde_json::Value {
    let mut recent: Vec<f64> = figures.recent_ms.iter().copied().collect();
    recent.sort_by(f64::total_cmp);
    let at = |q: f64| {
        recent
            .get(((recent.len() as f64 * q) as usize).min(recent.len().saturating_sub(1)))
            .copied()
    };
    serde_json::json!({
        "processed": figures.counters.processed,
        "skipped": figures.counters.skipped,
        "dropped_by_queue": figures.dropped_by_queue,
        "bad": figures.counters.bad,
        "stream_restarts": figures.stream_restarts,
        "frame_ms_median": at(0.5),
        "frame_ms_p95": at(0.95),
    })
}
