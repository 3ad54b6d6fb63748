//! The listening side: `Agent.audio` subscribed while ASR is enabled, segmented on a thread of its own.
//!
//! The segmenter holds the WebRTC detector, which is not `Send`, so it lives on a dedicated thread fed through a
//! bounded queue. Overflow policy: when the thread falls behind by `QUEUE` messages (about 20 s of audio) new
//! messages are dropped and counted; the pipeline notices the hole in the sequence and restarts cleanly.
//!
//! With speculation on, the thread also reports pauses (an utterance whose audio is complete unless the voice
//! resumes), resumptions, and utterances abandoned because recognition was switched off while they were open.
//!
//! Besides utterances the thread reports voice activity (start and end of speech) on a broadcast channel; only
//! the transcript relay listens to it, so with several satellites each change is published once.

use agent_contract::channels;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc as std_mpsc;
use std::time::Duration;

use bytes::Bytes;
use flow::Client;
use tokio::sync::{broadcast, mpsc, watch};

use super::error::SatelliteError;
use crate::activity::{self, VoiceActivity};
use crate::segmenter::SegmenterConfig;
use crate::stream::{AudioMessage, AudioStream, ClockedUtterance, StreamEvent};
use crate::turn::Turn;

/// Messages the segmentation thread may fall behind by before new ones are dropped.
const QUEUE: usize = 1024;
/// An open utterance is closed when the stream has been silent (no messages) this long: as long as the stream may
/// be late (a starved page sends nothing for a second or more, then all of it), so that a late stream is not cut.
const STALL: Duration = Duration::from_micros(crate::stream::MAX_LATENESS_US);
/// Voice-activity changes come a few per utterance; a relay that falls this far behind loses the oldest (and logs
/// how many), which only costs listeners a stale start or end.
const ACTIVITY_QUEUE: usize = 64;

/// Work for the segmentation thread.
#[derive(Debug)]
pub enum Feed {
    Audio {
        seq: u64,
        ts_us: u64,
        pcm: Bytes,
    },
    /// The stream ended (channel removed): close what is open.
    Flush,
    /// ASR was switched off: forget everything.
    Discard,
    /// A chunk of the agent's own speech (`Agent.speech`), for own-voice suppression (`whisper_sat::echo`).
    Reference {
        ts_us: u64,
        framing: Option<(u32, u32)>,
        pcm: Bytes,
    },
    /// The agent's speech was stopped (`speech_stop` on `Agent.avatar`).
    ReferenceStopped {
        ts_us: u64,
    },
    /// This satellite is decoding the pause of utterance `id` that ended speech at `speech_end_us` (`verdict`
    /// `None`), or has judged its transcript: the end of the turn follows the verdict (`Segmenter::turn`).
    Turn {
        id: String,
        speech_end_us: u64,
        verdict: Option<Turn>,
    },
    /// The satellite decoding utterance `id` ended it at the pause after `speech_end_us`, its segmenter closing
    /// it at `closed_us`: end it there too (`AudioStream::ended_elsewhere`).
    Ended {
        id: String,
        speech_end_us: u64,
        closed_us: u64,
    },
}

/// What the segmentation thread found, for the claiming side.
#[derive(Debug)]
pub enum Heard {
    /// The utterance paused for its post-roll: this is what it will be if it ends now (speculation only).
    Paused(ClockedUtterance),
    /// The voice of the paused utterance `id` came back (speculation only).
    Resumed { id: String },
    /// An utterance ended: transcribe it.
    Ended(ClockedUtterance),
    /// Recognition was switched off while the paused utterance `id` was open: it will never end (speculation only).
    Abandoned { id: String },
}

/// Handle on the segmentation thread.
#[derive(Debug, Clone)]
pub struct Listener {
    feed: std_mpsc::SyncSender<Feed>,
    pub dropped: Arc<AtomicU64>,
    /// Voice activity as the segmenter finds it.
    pub activity: broadcast::Sender<VoiceActivity>,
}

impl Listener {
    /// Starts the segmentation thread; utterances come out of the returned receiver, and with `speculate` their
    /// pauses too.
    pub fn start(
        cfg: SegmenterConfig,
        speculate: bool,
    ) -> Result<(Listener, mpsc::Receiver<Heard>), SatelliteError> {
        // Built here to report a bad configuration to the caller, and again on the thread that owns it.
        drop(AudioStream::new(cfg.clone())?);
        let (feed, rx) = std_mpsc::sync_channel::<Feed>(QUEUE);
        // Utterances (and their pauses) are a few per minute; 64 is ample, and the sender waits rather than lose one.
        let (utt_tx, utt_rx) = mpsc::channel(64);
        let (activity, _) = broadcast::channel(ACTIVITY_QUEUE);
        let activity_tx = activity.clone();
        std::thread::Builder::new().name("segmenter".into()).spawn(
            move || match AudioStream::new(cfg) {
                Ok(mut stream) => segment(&mut stream, &rx, &utt_tx, &activity_tx, speculate),
                Err(e) => tracing::error!("audio pipeline: {e}"),
            },
        )?;
        Ok((
            Listener {
                feed,
                dropped: Arc::new(AtomicU64::new(0)),
                activity,
            },
            utt_rx,
        ))
    }

    /// Queues work without waiting; counts what the full queue refuses.
    pub fn send(&self, item: Feed) {
        if let Err(std_mpsc::TrySendError::Full(_)) = self.feed.try_send(item) {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

fn segment(
    stream: &mut AudioStream,
    rx: &std_mpsc::Receiver<Feed>,
    out: &mpsc::Sender<Heard>,
    activity_out: &broadcast::Sender<VoiceActivity>,
    speculate: bool,
) {
    let mut events = Vec::new();
    // While audio flows, a stall closes open speech; while none does, the thread sleeps until work arrives.
    let mut flowing = false;
    loop {
        let item = if flowing {
            match rx.recv_timeout(STALL) {
                Ok(item) => item,
                Err(std_mpsc::RecvTimeoutError::Timeout) => Feed::Flush,
                Err(std_mpsc::RecvTimeoutError::Disconnected) => return,
            }
        } else {
            match rx.recv() {
                Ok(item) => item,
                Err(_) => return,
            }
        };
        // A verdict is not audio: the stream is still flowing (or not) as before it.
        flowing = match item {
            Feed::Audio { .. } => true,
            Feed::Turn { .. }
            | Feed::Ended { .. }
            | Feed::Reference { .. }
            | Feed::ReferenceStopped { .. } => flowing,
            Feed::Flush | Feed::Discard => false,
        };
        // Switched off: open speech still ends for the listeners, but nothing is transcribed.
        let discard = matches!(item, Feed::Discard);
        let result = match item {
            Feed::Audio { seq, ts_us, pcm } => stream.push(
                AudioMessage {
                    seq,
                    ts_us,
                    pcm: &pcm,
                },
                &mut events,
            ),
            Feed::Flush => stream.finish(&mut events),
            Feed::Discard => stream.finish(&mut events),
            Feed::Turn {
                id,
                speech_end_us,
                verdict,
            } => {
                stream.turn(&id, speech_end_us, verdict, &mut events);
                Ok(())
            }
            Feed::Ended {
                id,
                speech_end_us,
                closed_us,
            } => {
                stream.ended_elsewhere(&id, speech_end_us, closed_us, &mut events);
                Ok(())
            }
            Feed::Reference {
                ts_us,
                framing,
                pcm,
            } => {
                stream.reference(ts_us, framing, &pcm);
                Ok(())
            }
            Feed::ReferenceStopped { ts_us } => {
                stream.reference_stopped(ts_us);
                Ok(())
            }
        };
        if let Err(e) = result {
            tracing::error!("audio pipeline: {e}");
        }
        for ev in events.drain(..) {
            if let Some(change) = activity::of_event(&ev) {
                tracing::debug!(?change, "voice activity");
                // No receiver (this satellite is not the relay) is the common case, not an error.
                let _ = activity_out.send(change);
            }
            let heard = match ev {
                // A holder of its pause must let the claim go: the end will never come.
                StreamEvent::Utterance(u) if discard => {
                    speculate.then_some(Heard::Abandoned { id: u.id })
                }
                StreamEvent::Utterance(u) => {
                    tracing::debug!(id = %u.id, seconds = u.audio.len() as f64 / 16_000.0, "utterance found");
                    Some(Heard::Ended(u))
                }
                StreamEvent::Paused(u) => {
                    tracing::debug!(id = %u.id, seconds = u.audio.len() as f64 / 16_000.0, "utterance paused");
                    speculate.then_some(Heard::Paused(u))
                }
                StreamEvent::Resumed { id, .. } => {
                    tracing::debug!(%id, "utterance resumed");
                    speculate.then_some(Heard::Resumed { id })
                }
                StreamEvent::Started { start_us, .. } => {
                    tracing::trace!(start_us, "speech started");
                    None
                }
                StreamEvent::Confirmed { start_us, .. } => {
                    tracing::trace!(start_us, "speech confirmed");
                    None
                }
                StreamEvent::Dropped { start_us, .. } => {
                    tracing::debug!(start_us, "speech dropped as too short or noise");
                    None
                }
                StreamEvent::Restarted => {
                    tracing::debug!("audio stream restarted");
                    None
                }
            };
            if let Some(heard) = heard
                && out.blocking_send(heard).is_err()
            {
                return;
            }
        }
    }
}

/// Keeps the microphone's subscription open exactly while ASR is enabled, feeding the listener.
///
/// The microphone is `Agent.audio.clean` (the server's echo module: `Agent.audio` less the agent's own voice) when
/// the hub has it, `Agent.audio` otherwise; a satellite listening to the raw stream moves to the cleaned one when
/// it appears (a satellite that connected before the module made its channel).
pub async fn follow_audio(
    client: Client,
    listener: Listener,
    mut enabled: watch::Receiver<bool>,
) -> Result<(), SatelliteError> {
    let mut events = client.events();
    loop {
        while !*enabled.borrow_and_update() {
            enabled.changed().await?;
        }
        let name = microphone_channel(&client).await;
        let sub = client.subscribe(name).await?;
        tracing::info!("ASR enabled: listening to {name}");
        loop {
            tokio::select! {
                data = sub.recv() => {
                    let Some(d) = data else { return Ok(()) };
                    if d.payload.is_empty() {
                        // `Agent.audio.clean`'s stream break: the microphone's stream started again.
                        listener.send(Feed::Flush);
                    } else {
                        listener.send(Feed::Audio { seq: d.seq, ts_us: d.ts_us, pcm: d.payload });
                    }
                }
                changed = enabled.changed() => {
                    changed?;
                    if !*enabled.borrow() {
                        break;
                    }
                }
                event = events.recv() => match event {
                    Ok(flow::ClientEvent::ChannelAdded(info))
                        if info.name == channels::AUDIO_CLEAN.name && name != channels::AUDIO_CLEAN.name =>
                    {
                        tracing::info!("{} appeared: moving to it", channels::AUDIO_CLEAN.name);
                        break;
                    }
                    Err(broadcast::error::RecvError::Closed) => return Ok(()),
                    _ => {}
                },
            }
        }
        // Dropping the subscription unsubscribes: a disabled satellite costs the hub nothing.
        drop(sub);
        if *enabled.borrow() {
            // Moving to the cleaned stream: what was open on the raw one ends where it stands.
            listener.send(Feed::Flush);
        } else {
            listener.send(Feed::Discard);
            tracing::info!("ASR disabled: stopped listening");
        }
    }
}

/// The channel this satellite hears the microphone on: the cleaned one when the hub has it.
async fn microphone_channel(client: &Client) -> &'static str {
    if client.channel(channels::AUDIO_CLEAN.name).await.is_ok() {
        channels::AUDIO_CLEAN.name
    } else {
        channels::AUDIO.name
    }
}

/// Follows the agent's own speech on `Agent.speech`, and its stops on `Agent.avatar`, for the listener's own-voice
/// suppression. Speech payloads start with the `[utterance u32][offset u32]` header when the channel header
/// announces `framing` (docs/browser-link.md).
/// Does nothing unless `enabled` (`whisper-sat run --echo-gate`).
pub async fn follow_speech(
    client: Client,
    listener: Listener,
    enabled: bool,
) -> Result<(), SatelliteError> {
    if !enabled {
        return Ok(());
    }
    let sub = client.subscribe(channels::SPEECH.name).await?;
    let avatar = client.subscribe(channels::AVATAR.name).await?;
    loop {
        let d = tokio::select! {
            d = sub.recv() => d,
            a = avatar.recv() => {
                let Some(a) = a else { return Ok(()) };
                if matches!(
                    serde_json::from_slice::<agent_contract::avatar::AvatarCommand>(&a.payload),
                    Ok(agent_contract::avatar::AvatarCommand::SpeechStop { utterance: None, .. })
                ) {
                    listener.send(Feed::ReferenceStopped { ts_us: a.ts_us });
                }
                continue;
            }
        };
        let Some(d) = d else { return Ok(()) };
        let framed = sub.info().is_some_and(|info| {
            serde_json::from_str::<serde_json::Value>(&info.header)
                .is_ok_and(|h| h.get("framing").is_some())
        });
        let (framing, pcm) = if framed && d.payload.len() >= 8 {
            let word = |i: usize| {
                u32::from_le_bytes([
                    d.payload[i],
                    d.payload[i + 1],
                    d.payload[i + 2],
                    d.payload[i + 3],
                ])
            };
            (Some((word(0), word(4))), d.payload.slice(8..))
        } else {
            (None, d.payload.clone())
        };
        listener.send(Feed::Reference {
            ts_us: d.ts_us,
            framing,
            pcm,
        });
    }
}

/// Follows `Agent.ctrl` for `{"asr": true|false}`.
pub async fn follow_ctrl(
    client: Client,
    enabled: watch::Sender<bool>,
) -> Result<(), SatelliteError> {
    let sub = client.subscribe(channels::CTRL.name).await?;
    while let Some(d) = sub.recv().await {
        match serde_json::from_slice::<agent_contract::ctrl::Ctrl>(&d.payload) {
            Ok(ctrl) => {
                if let Some(on) = ctrl.asr {
                    enabled.send_replace(on);
                }
            }
            Err(e) => tracing::warn!(
                "ignoring an Agent.ctrl message that is not the contract's shape: {e}"
            ),
        }
    }
    Ok(())
}
