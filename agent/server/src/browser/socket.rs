//! One page's WebSocket: the welcome, the role, media from the page into the hub, hub channels to the page, and the
//! once-a-second status with drop counters and frame-rate advice.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use axum::extract::ws::{CloseFrame, Message, WebSocket};
use bytes::Bytes;
use futures_util::{SinkExt, StreamExt};
use serde_json::json;
use tokio::sync::mpsc;
use tracing::Instrument;

use super::downlink::Downlink;
use super::pacing::FpsAdvice;
use super::role::{Claim, PageId};
use super::state::{Notice, Shared, lock};
use super::uplink::Uplink;
use super::wire::{self, FrameKind, PageMessage, PageText, RoleState};
use agent_contract::link::{self, Dropped};

/// Messages waiting for the page's socket; producers wait for room (see `downlink`), so this bounds memory.
const OUT_QUEUE: usize = 64;

/// Close codes (RFC 6455).
const CLOSE_AWAY: u16 = 1001;
const CLOSE_UNSUPPORTED: u16 = 1003;
const CLOSE_TOO_BIG: u16 = 1009;
const CLOSE_ERROR: u16 = 1011;

/// Why the loop ended.
enum End {
    PageClosed,
    Close(u16, String),
}

/// Per-second counters for the status message.
#[derive(Debug, Default)]
struct Meter {
    audio_frames: u64,
    video_frames: u64,
    sum_sq: f64,
    samples: u64,
}

/// Runs one page's socket until it closes, then frees `token` for a reconnect (its first 8 characters tag the
/// logs).
pub async fn run(shared: Arc<Shared>, ws: WebSocket, token: &str) {
    let page: PageId = shared.next_page.fetch_add(1, Ordering::Relaxed);
    let tag = token.get(..8).unwrap_or(token).to_string();
    let span = tracing::info_span!("page", id = page, session = %tag);
    serve(shared, ws, page, token).instrument(span).await;
}

async fn serve(shared: Arc<Shared>, ws: WebSocket, page: PageId, token: &str) {
    let Some(client) = shared.client.get().cloned() else {
        // The route checks this before upgrading; the module cannot unset it.
        lock(&shared.sessions).unbind(token, Instant::now());
        return;
    };
    tracing::info!("page connected");

    let (mut sink, mut stream) = ws.split();
    let (out, mut out_rx) = mpsc::channel::<Message>(OUT_QUEUE);
    let writer = tokio::spawn(async move {
        while let Some(msg) = out_rx.recv().await {
            let closing = matches!(msg, Message::Close(_));
            if sink.send(msg).await.is_err() || closing {
                break;
            }
        }
    });
    let (notice_tx, mut notices) = mpsc::channel(4);
    lock(&shared.pages).insert(page, notice_tx);

    let mut conn = Conn {
        shared: shared.clone(),
        client: client.clone(),
        page,
        out: out.clone(),
        uplink: Uplink::default(),
        dropped: Dropped::default(),
        meter: Meter::default(),
        advice: FpsAdvice::default(),
    };
    let end = match Downlink::start(&client, out.clone()).await {
        Err(e) => End::Close(CLOSE_ERROR, format!("hub unavailable: {e}")),
        Ok(downlink) => {
            conn.welcome().await;
            let mut shutdown = shared.shutdown.clone();
            let mut tick = tokio::time::interval(Duration::from_secs(1));
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                tokio::select! {
                    _ = shutdown.changed() => break End::Close(CLOSE_AWAY, "server shutting down".into()),
                    msg = stream.next() => match msg {
                        None | Some(Ok(Message::Close(_))) => break End::PageClosed,
                        Some(Err(e)) => break read_error(e),
                        Some(Ok(Message::Binary(b))) => if let Err(e) = conn.binary(b) { break e },
                        Some(Ok(Message::Text(t))) => if let Err(e) = conn.text(t.as_str()).await { break e },
                        Some(Ok(_)) => {}
                    },
                    Some(notice) = notices.recv() => match notice {
                        Notice::Granted => conn.send_role(RoleState::Granted).await,
                    },
                    _ = tick.tick() => conn.status(downlink.dropped()).await,
                }
            }
        }
    };

    // Leave the role first, so the channels are removed before the next page creates them again.
    conn.uplink.close();
    lock(&shared.pages).remove(&page);
    conn.leave_role();
    // Free the token before the page hears the close, so that it can reconnect with it at once.
    lock(&shared.sessions).unbind(token, Instant::now());
    match end {
        End::PageClosed => tracing::info!("page disconnected"),
        End::Close(code, reason) => {
            if code == CLOSE_UNSUPPORTED || code == CLOSE_TOO_BIG {
                tracing::warn!(code, %reason, "closing page socket: malformed input");
            } else {
                tracing::info!(code, %reason, "closing page socket");
            }
            let frame = CloseFrame {
                code,
                reason: reason.into(),
            };
            let _ = out.send(Message::Close(Some(frame))).await;
        }
    }
    drop(conn);
    drop(out);
    let _ = writer.await;
}

/// How a failed read ends the socket: a message over the size limit is the page's fault and gets 1009 with the
/// reason; anything else means the connection is gone.
fn read_error(e: axum::Error) -> End {
    match e.into_inner().downcast::<tungstenite::Error>() {
        Ok(e) if matches!(*e, tungstenite::Error::Capacity(_)) => End::Close(
            CLOSE_TOO_BIG,
            format!(
                "{e} (a message may hold at most {} bytes)",
                wire::HEADER_BYTES + wire::MAX_VIDEO_BYTES
            ),
        ),
        Ok(e) => {
            tracing::debug!(error = %e, "page socket failed");
            End::PageClosed
        }
        Err(e) => {
            tracing::debug!(error = %e, "page socket failed");
            End::PageClosed
        }
    }
}

struct Conn {
    shared: Arc<Shared>,
    client: flow::Client,
    page: PageId,
    out: mpsc::Sender<Message>,
    uplink: Uplink,
    dropped: Dropped,
    meter: Meter,
    advice: FpsAdvice,
}

impl Conn {
    async fn send_json(&self, value: serde_json::Value) {
        let _ = self.out.send(Message::Text(value.to_string().into())).await;
    }

    async fn welcome(&self) {
        let holder = lock(&self.shared.roles).holder();
        let role = if holder.is_some() {
            RoleState::Busy
        } else {
            RoleState::Free
        };
        let welcome = link::Welcome {
            kind: "welcome".into(),
            version: 1,
            session: self.page,
            server: concat!("robot-agent ", env!("CARGO_PKG_VERSION")).into(),
            audio: link::AudioFormat {
                rate: 22050,
                channels: 1,
                format: "s16le".into(),
                chunk_ms: 20,
            },
            video: link::VideoFormat {
                width: 640,
                height: 360,
                fps: 15,
                format: "jpeg".into(),
            },
            fft: link::FftFormat::of_spectra(self.shared.fft_hop),
            role: link::RoleInfo {
                state: role.as_str().into(),
            },
            language: self.shared.language.clone(),
            voice: self.shared.voice.into(),
        };
        self.send_json(serde_json::to_value(welcome).unwrap_or_default())
            .await;
    }

    async fn send_role(&self, state: RoleState) {
        self.send_json(json!({"type": "role", "state": state}))
            .await;
    }

    fn is_holder(&self) -> bool {
        lock(&self.shared.roles).holder() == Some(self.page)
    }

    /// Gives the role up (or withdraws a waiting claim) and hands it to the next page in line.
    fn leave_role(&mut self) {
        self.uplink.close();
        let next = lock(&self.shared.roles).leave(self.page);
        if let Some(next) = next {
            let tx = lock(&self.shared.pages).get(&next).cloned();
            if let Some(tx) = tx {
                // A full notice queue means that page already has a notice pending: nothing is lost.
                let _ = tx.try_send(Notice::Granted);
            }
        }
    }

    fn binary(&mut self, frame: Bytes) -> Result<(), End> {
        let media =
            wire::parse_media(frame).map_err(|e| End::Close(CLOSE_UNSUPPORTED, e.to_string()))?;
        let accepted = match media.kind {
            FrameKind::Audio => {
                self.meter.audio_frames += 1;
                for s in media.payload.chunks_exact(2) {
                    let v = f64::from(i16::from_le_bytes([s[0], s[1]])) / 32768.0;
                    self.meter.sum_sq += v * v;
                }
                self.meter.samples += (media.payload.len() / 2) as u64;
                self.uplink.audio(media.payload)
            }
            FrameKind::Video => {
                self.meter.video_frames += 1;
                self.uplink.video(media.payload)
            }
            // parse_media only returns page -> server kinds.
            FrameKind::Speech | FrameKind::Spectrum => false,
        };
        if !accepted {
            self.dropped.not_holder += 1;
        }
        Ok(())
    }

    async fn text(&mut self, text: &str) -> Result<(), End> {
        let msg = match wire::parse_text(text) {
            Ok(PageText::Message(m)) => m,
            Ok(PageText::Unknown(kind)) => {
                self.send_json(json!({"type": "error", "code": "unknown_type", "message": format!("unknown message type {kind:?}")})).await;
                return Ok(());
            }
            Err(e) => return Err(End::Close(CLOSE_UNSUPPORTED, e.to_string())),
        };
        match msg {
            PageMessage::Hello {
                version,
                client,
                autostart,
            } => {
                tracing::info!(version, %client, autostart, "hello");
            }
            PageMessage::Claim => {
                let claim = lock(&self.shared.roles).claim(self.page);
                let state = match claim {
                    Claim::Granted => RoleState::Granted,
                    Claim::Busy => RoleState::Busy,
                };
                tracing::info!(?state, "role claim");
                self.send_role(state).await;
            }
            PageMessage::Release => {
                self.leave_role();
                self.send_role(RoleState::Released).await;
            }
            PageMessage::Media { audio, video } => {
                if !self.is_holder() {
                    return Ok(());
                }
                if let Err(e) = self.uplink.set_media(&self.client, audio, video).await {
                    tracing::warn!(error = %e, "cannot create media channels");
                    self.send_json(
                        json!({"type": "error", "code": "channel", "message": e.to_string()}),
                    )
                    .await;
                }
            }
            PageMessage::Ctrl { data } => {
                if !self.is_holder() {
                    return Ok(());
                }
                if let Err(e) = self.uplink.ctrl(&self.client, data.to_string()).await {
                    self.send_json(
                        json!({"type": "error", "code": "channel", "message": e.to_string()}),
                    )
                    .await;
                }
            }
            PageMessage::Played { utterance, at_ms } => {
                // The holder's page is the one the user hears (docs/telemetry.md).
                if !self.is_holder() {
                    return Ok(());
                }
                let started = agent_contract::say::PlaybackStarted { utterance, at_ms };
                // One small message per utterance; a full send queue drops it (counted by the SDK).
                if let Some(publisher) = self.shared.playback.get()
                    && let Err(e) =
                        publisher.try_publish(serde_json::to_vec(&started).unwrap_or_default())
                {
                    tracing::debug!("playback start not published: {e}");
                }
            }
            PageMessage::Ping { t } => {
                // The server's clock rides along, so the page can put hub timestamps on its own clock.
                let server_ms = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0.0, |d| d.as_secs_f64() * 1000.0);
                let pong = link::Pong {
                    kind: "pong".into(),
                    t,
                    server_ms,
                };
                self.send_json(serde_json::to_value(pong).unwrap_or_default())
                    .await
            }
        }
        Ok(())
    }

    async fn status(&mut self, to_page: u64) {
        self.dropped.video_queue = self.uplink.video_drops();
        self.dropped.to_page = to_page;
        let fps = self.advice.tick(self.dropped.video_queue);
        let m = std::mem::take(&mut self.meter);
        let level = if m.samples > 0 && m.sum_sq > 0.0 {
            Some(10.0 * (m.sum_sq / m.samples as f64).log10())
        } else {
            None
        };
        let role = if self.is_holder() {
            "holder"
        } else if lock(&self.shared.roles).is_waiting(self.page) {
            "waiting"
        } else {
            "none"
        };
        let (audio, video) = self.uplink.sending();
        let status = link::Status {
            kind: "status".into(),
            role: role.into(),
            incoming: link::Incoming {
                audio_fps: m.audio_frames,
                video_fps: m.video_frames,
                audio_level_dbfs: level,
            },
            sending: link::Sending { audio, video },
            dropped: self.dropped,
            audio_dropped: self.uplink.audio_drops(),
            advice: link::Advice { video_fps: fps },
        };
        // Status comes every second: when the page is this far behind, skipping one loses nothing.
        let _ = self.out.try_send(Message::Text(
            serde_json::to_string(&status).unwrap_or_default().into(),
        ));
    }
}
