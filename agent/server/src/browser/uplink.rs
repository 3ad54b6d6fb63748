//! The role holder's media into the hub: `Agent.audio` and `Agent.video` exist while the page sends them, and
//! `Agent.ctrl` (the page's switches for other modules) while it sends any.
//!
//! Each medium has a lane: a bounded drop-oldest queue between the socket and a task that publishes. The socket
//! never waits for the hub; when the hub side is slower than the page, the oldest waiting item is dropped and
//! counted (video keeps 4 frames, audio 10 s). Closing a lane ends its task, whose `Publisher` is dropped, which
//! removes the channel from the hub.

use std::sync::Arc;

use bytes::Bytes;
use flow::queue::DropOldest;
use tokio::task::JoinHandle;

use agent_contract::channels;

/// Frames kept while the hub side catches up (about a quarter second at 15 fps): enough to ride out a scheduling
/// hiccup on a busy machine; anything older is worthless and dropped.
const VIDEO_QUEUE: usize = 4;
/// 500 chunks of 20 ms: ten seconds of audio (440 KB). A page whose main thread was starved sends what it
/// captured meanwhile at once, seconds of it; those chunks are late, not stale, and a lane of one second dropped
/// the first words of the question they held. Whisper accepts late audio (`whisper_sat::stream`), so only a hub
/// side stuck for ten seconds loses any.
const AUDIO_QUEUE: usize = 500;

#[derive(Debug)]
struct Lane {
    queue: Arc<DropOldest<Bytes>>,
    task: JoinHandle<()>,
}

impl Lane {
    async fn open(
        client: &flow::Client,
        name: &str,
        header: &str,
        capacity: usize,
    ) -> Result<Lane, flow::FlowError> {
        let publisher = client.publisher(name, header).await?;
        let queue = Arc::new(DropOldest::new(capacity));
        let rx = queue.clone();
        let task = tokio::spawn(async move {
            while let Some(item) = rx.pop().await {
                if let Err(e) = publisher.publish(item).await {
                    tracing::warn!(channel = publisher.name(), error = %e, "publishing stopped");
                    break;
                }
            }
            // `publisher` drops here: the hub removes the channel.
        });
        Ok(Lane { queue, task })
    }
}

impl Drop for Lane {
    fn drop(&mut self) {
        self.queue.close();
        // The task may be waiting on a full hub link; it holds nothing worth finishing.
        self.task.abort();
    }
}

/// The holder's channels; empty for pages that do not hold the role.
#[derive(Debug, Default)]
pub struct Uplink {
    audio: Option<Lane>,
    video: Option<Lane>,
    ctrl: Option<flow::Publisher>,
    /// Drops of lanes already closed, so the status counters never go backwards.
    closed_video_drops: u64,
    closed_audio_drops: u64,
}

impl Uplink {
    /// Opens or closes lanes to match what the page says it sends.
    pub async fn set_media(
        &mut self,
        client: &flow::Client,
        audio: bool,
        video: bool,
    ) -> Result<(), flow::FlowError> {
        if !audio {
            self.close_audio();
        }
        if !video {
            self.close_video();
        }
        if audio && self.audio.is_none() {
            self.audio = Some(
                Lane::open(
                    client,
                    channels::AUDIO.name,
                    channels::headers::AUDIO,
                    AUDIO_QUEUE,
                )
                .await?,
            );
        }
        if video && self.video.is_none() {
            self.video = Some(
                Lane::open(
                    client,
                    channels::VIDEO.name,
                    channels::headers::VIDEO,
                    VIDEO_QUEUE,
                )
                .await?,
            );
        }
        // Agent.ctrl exists while the holder sends media, so that its readers (ASR, TTS) are subscribed before the
        // first control message: a channel created for one message would lose it to sticky subscribers.
        if (audio || video) && self.ctrl.is_none() {
            self.ctrl = Some(
                client
                    .publisher(channels::CTRL.name, channels::headers::CTRL)
                    .await?,
            );
        }
        Ok(())
    }

    /// Closes everything (role released or socket gone); the channels disappear from the hub.
    pub fn close(&mut self) {
        self.close_audio();
        self.close_video();
        self.ctrl = None;
    }

    fn close_audio(&mut self) {
        if let Some(l) = self.audio.take() {
            self.closed_audio_drops += l.queue.dropped();
        }
    }

    fn close_video(&mut self) {
        if let Some(l) = self.video.take() {
            self.closed_video_drops += l.queue.dropped();
        }
    }

    /// Queues an audio chunk; returns false when no audio lane is open.
    pub fn audio(&self, pcm: Bytes) -> bool {
        self.audio.as_ref().map(|l| l.queue.push(pcm)).is_some()
    }

    /// Queues a video frame; returns false when no video lane is open.
    pub fn video(&self, jpeg: Bytes) -> bool {
        self.video.as_ref().map(|l| l.queue.push(jpeg)).is_some()
    }

    /// Publishes a control message on `Agent.ctrl`, creating the channel on first use.
    pub async fn ctrl(
        &mut self,
        client: &flow::Client,
        json: String,
    ) -> Result<(), flow::FlowError> {
        if self.ctrl.is_none() {
            self.ctrl = Some(
                client
                    .publisher(channels::CTRL.name, channels::headers::CTRL)
                    .await?,
            );
        }
        match &self.ctrl {
            Some(p) => p.publish(json).await,
            None => Ok(()),
        }
    }

    pub fn video_drops(&self) -> u64 {
        self.closed_video_drops + self.video.as_ref().map_or(0, |l| l.queue.dropped())
    }

    pub fn audio_drops(&self) -> u64 {
        self.closed_audio_drops + self.audio.as_ref().map_or(0, |l| l.queue.dropped())
    }

    pub fn sending(&self) -> (bool, bool) {
        (self.audio.is_some(), self.video.is_some())
    }
}
