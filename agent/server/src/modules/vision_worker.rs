//! The vision detectors' own thread, at background priority: on a busy machine the spoken turn's work (voice
//! activity, the decode, the rule, speech) goes first, and the detectors take what is left.
//!
//! The thread lowers itself to `flow::priority::BACKGROUND_NICE` before it builds the pipeline, so the thread pools
//! the detectors start (ONNX Runtime's, OpenCV's) inherit the level. It takes one job at a time: the module awaits
//! each frame's result before it sends the next, and newer frames wait in the module's drop-oldest subscription,
//! so a slow thread skips frames rather than queueing them.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError, mpsc};

use agent_face::{Acquaintance, Descriptor};

use agent_vision::pipeline::PipelineParams;
use agent_vision::{FrameDetections, ProcessError, VisionPipeline};
use anyhow::{Context, anyhow};
use bytes::Bytes;
use tokio::sync::oneshot;
use tracing::{info, warn};

/// Work for the thread.
#[derive(Debug)]
enum Job {
    Frame {
        jpeg: Bytes,
        seq: u64,
        ts_us: u64,
        reply: oneshot::Sender<Result<FrameDetections, ProcessError>>,
    },
    /// A new stream began: forget the old one's motion history.
    Reset,
}

/// What the module tells the per-face analysis between frames, and what it reads back, without a job in the
/// queue (the queue holds one frame; a voice event must never make a frame wait or be refused).
#[derive(Debug, Default)]
pub struct PeopleLink {
    /// A voice is heard now (the user's voice activity).
    voice: AtomicBool,
    /// A new list of acquaintances, taken by the thread before its next frame.
    known: Mutex<Option<Vec<Acquaintance>>>,
    /// The face `learn_face` means after the last frame, with its descriptor.
    learnable: Mutex<Option<(u64, Descriptor)>>,
}

impl PeopleLink {
    pub fn set_voice(&self, active: bool) {
        self.voice.store(active, Ordering::Relaxed);
    }

    pub fn set_known(&self, known: Vec<Acquaintance>) {
        *self.known.lock().unwrap_or_else(PoisonError::into_inner) = Some(known);
    }

    pub fn learnable(&self) -> Option<(u64, Descriptor)> {
        self.learnable
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }
}

/// The handle the module keeps; dropping it ends the thread after its current frame.
#[derive(Debug)]
pub struct VisionWorker {
    jobs: mpsc::SyncSender<Job>,
    people: Arc<PeopleLink>,
}

impl VisionWorker {
    /// Starts the thread and builds the detectors on it (loading the network or the cascades blocks).
    pub async fn start(params: PipelineParams) -> anyhow::Result<VisionWorker> {
        // One job at a time is all the module sends; a second slot lets a reset follow a frame without waiting.
        let (jobs, queue) = mpsc::sync_channel::<Job>(2);
        let (ready_tx, ready) = oneshot::channel();
        let people = Arc::new(PeopleLink::default());
        let link = people.clone();
        std::thread::Builder::new()
            .name("vision".into())
            .spawn(move || {
                match flow::priority::lower_this_thread(flow::priority::BACKGROUND_NICE) {
                    Ok(nice) => info!(nice, "vision: detectors run at background priority"),
                    Err(e) => warn!("vision: detectors keep the server's priority: {e}"),
                }
                let mut pipeline = match VisionPipeline::new(params) {
                    Ok(p) => {
                        let _ = ready_tx.send(Ok(()));
                        p
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                while let Ok(job) = queue.recv() {
                    match job {
                        Job::Frame {
                            jpeg,
                            seq,
                            ts_us,
                            reply,
                        } => {
                            if let Some(analysis) = pipeline.people() {
                                analysis.set_voice(link.voice.load(Ordering::Relaxed));
                                let known = link
                                    .known
                                    .lock()
                                    .unwrap_or_else(PoisonError::into_inner)
                                    .take();
                                if let Some(known) = known {
                                    analysis.set_known(known);
                                }
                            }
                            let result = pipeline.process_jpeg(&jpeg, seq, ts_us);
                            if let Some(analysis) = pipeline.people() {
                                *link
                                    .learnable
                                    .lock()
                                    .unwrap_or_else(PoisonError::into_inner) = analysis.learnable();
                            }
                            let _ = reply.send(result);
                        }
                        Job::Reset => pipeline.reset_stream(),
                    }
                }
            })
            .context("starting the vision thread")?;
        ready
            .await
            .map_err(|_| anyhow!("the vision thread ended while starting"))?
            .context("[modules.vision]")?;
        Ok(VisionWorker { jobs, people })
    }

    /// Runs the detectors on one frame; an error when the thread is gone (it panicked).
    pub async fn process(
        &self,
        jpeg: Bytes,
        seq: u64,
        ts_us: u64,
    ) -> anyhow::Result<Result<FrameDetections, ProcessError>> {
        let (reply, result) = oneshot::channel();
        self.jobs
            .try_send(Job::Frame {
                jpeg,
                seq,
                ts_us,
                reply,
            })
            .map_err(|_| anyhow!("the vision thread is gone or has more than one frame"))?;
        result.await.context("the vision thread stopped")
    }

    /// The per-face analysis's side door (voice activity, acquaintances, the face to learn).
    pub fn people(&self) -> &PeopleLink {
        &self.people
    }

    /// Tells the detectors a new stream began.
    pub fn reset_stream(&self) {
        let _ = self.jobs.try_send(Job::Reset);
    }
}
