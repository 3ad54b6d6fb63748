//! Hub channels to one page: avatar commands, detections, rule trace, turn latencies, the recording state, speech
//! PCM and the spectrum.
//!
//! Each channel has its own subscription (a drop-oldest queue in the SDK) and a small task that turns messages into
//! WebSocket frames and waits for room in the page's outgoing queue. A page that reads slowly therefore loses the
//! oldest messages of each channel (counted, reported as `dropped.to_page`), and never holds up the hub or other
//! pages.

use std::sync::Arc;

use axum::extract::ws::Message;
use bytes::Bytes;
use serde::de::IgnoredAny;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use super::wire::{FrameKind, encode_frame};
use agent_contract::channels;

/// How one channel's messages reach the page.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Route {
    /// JSON payload wrapped as `{"type":<name>,"data":<payload>}`.
    Json(&'static str),
    Speech,
    Spectrum,
}

const ROUTES: [(&str, Route); 7] = [
    (channels::AVATAR.name, Route::Json("avatar")),
    (channels::DETECTIONS.name, Route::Json("detections")),
    (channels::RULES.name, Route::Json("rules")),
    (channels::LATENCY.name, Route::Json("latency")),
    (channels::RECORDING.name, Route::Json("recording")),
    (channels::SPEECH.name, Route::Speech),
    (channels::AUDIO_FFT.name, Route::Spectrum),
];

/// The forwarders of one page; dropping it stops them and unsubscribes.
#[derive(Debug)]
pub struct Downlink {
    tasks: Vec<JoinHandle<()>>,
    subscriptions: Vec<Arc<flow::Subscription>>,
}

impl Downlink {
    pub async fn start(
        client: &flow::Client,
        out: mpsc::Sender<Message>,
    ) -> Result<Downlink, flow::FlowError> {
        let mut tasks = Vec::new();
        let mut subscriptions = Vec::new();
        for (name, route) in ROUTES {
            let sub = Arc::new(client.subscribe(name).await?);
            subscriptions.push(sub.clone());
            tasks.push(tokio::spawn(forward(sub, route, out.clone())));
        }
        Ok(Downlink {
            tasks,
            subscriptions,
        })
    }

    /// Messages dropped because this page read too slowly, over all channels.
    pub fn dropped(&self) -> u64 {
        self.subscriptions.iter().map(|s| s.dropped()).sum()
    }
}

impl Drop for Downlink {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

async fn forward(sub: Arc<flow::Subscription>, route: Route, out: mpsc::Sender<Message>) {
    let mut seq: u32 = 0;
    let mut rejected: u64 = 0;
    let mut speech = SpeechFraming::default();
    while let Some(data) = sub.recv().await {
        let msg = match route {
            Route::Json(kind) => match wrap_json(kind, &data.payload) {
                Some(text) => Message::Text(text.into()),
                None => {
                    rejected += 1;
                    if rejected.is_power_of_two() {
                        tracing::warn!(
                            channel = sub.name(),
                            rejected,
                            "payload is not JSON; not forwarded to pages"
                        );
                    }
                    continue;
                }
            },
            Route::Spectrum => {
                Message::Binary(encode_frame(FrameKind::Spectrum, seq, &[&data.payload]))
            }
            Route::Speech => {
                let framed = sub
                    .info()
                    .is_some_and(|i| i.header.contains("utterance-offset"));
                Message::Binary(speech.frame(seq, framed, &data.payload))
            }
        };
        seq = seq.wrapping_add(1);
        if out.send(msg).await.is_err() {
            return;
        }
    }
}

/// `{"type":kind,"data":payload}` for a payload that is valid JSON; `None` otherwise.
fn wrap_json(kind: &str, payload: &[u8]) -> Option<String> {
    serde_json::from_slice::<IgnoredAny>(payload).ok()?;
    let text = std::str::from_utf8(payload).ok()?;
    Some(format!(r#"{{"type":"{kind}","data":{text}}}"#))
}

/// Speech payloads framed by the publisher (`[utterance u32][offset u32][pcm]`) pass through; plain PCM gets
/// utterance 0 and a running sample offset.
#[derive(Debug, Default)]
struct SpeechFraming {
    offset: u32,
}

impl SpeechFraming {
    fn frame(&mut self, seq: u32, framed: bool, payload: &Bytes) -> Bytes {
        if framed {
            return encode_frame(FrameKind::Speech, seq, &[payload]);
        }
        let offset = self.offset;
        self.offset = self.offset.wrapping_add((payload.len() / 2) as u32);
        encode_frame(
            FrameKind::Speech,
            seq,
            &[&0u32.to_le_bytes(), &offset.to_le_bytes(), payload],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_is_wrapped_and_garbage_refused() {
        assert_eq!(
            wrap_json("avatar", br#"{"cmd":"blink"}"#).as_deref(),
            Some(r#"{"type":"avatar","data":{"cmd":"blink"}}"#)
        );
        assert_eq!(wrap_json("avatar", b"{\"cmd\":"), None);
        assert_eq!(wrap_json("avatar", b"\xff\xfe"), None);
    }

    #[test]
    fn plain_pcm_gets_utterance_zero_and_running_offsets() {
        let mut f = SpeechFraming::default();
        let a = f.frame(0, false, &Bytes::from_static(&[1, 0, 2, 0]));
        assert_eq!(&a[8..16], &[0, 0, 0, 0, 0, 0, 0, 0]);
        let b = f.frame(1, false, &Bytes::from_static(&[3, 0]));
        assert_eq!(&b[8..16], &[0, 0, 0, 0, 2, 0, 0, 0]);
        assert_eq!(&b[16..], &[3, 0]);
        let framed = f.frame(
            2,
            true,
            &Bytes::from_static(&[7, 0, 0, 0, 9, 0, 0, 0, 5, 0]),
        );
        assert_eq!(&framed[8..], &[7, 0, 0, 0, 9, 0, 0, 0, 5, 0]);
    }
}
