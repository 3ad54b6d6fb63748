//! The transcript relay: the one connection that owns `Agent.transcript`.
//!
//! Only a channel's owner may publish on it, and several satellites produce transcripts, so one of them (whichever
//! creates `Agent.transcript` first) also serves `Agent.asr.submit` and publishes what the others submit. If it
//! dies, the hub removes both channels and tells everyone; the survivors race to take the role over. The relay
//! publishes each utterance once, whatever is submitted twice.
//!
//! Previews (`"final": false`, the transcript of a pause before the end of the turn is decided) go out on
//! `Agent.transcript.pause` instead, without the once-per-utterance rule: the final transcript follows them.
//!
//! The relay also publishes voice activity (`{"vad":"start"|"end",...}`) from its own satellite's segmenter. Every
//! satellite segments the same stream into the same utterances, so the relay's view is everyone's, and the events go
//! out once however many satellites run; they need no round trip through the submit service.

use std::collections::VecDeque;

use flow::{Client, ClientEvent, ErrorCode, Publisher};
use tokio::sync::broadcast;

use super::error::SatelliteError;
use crate::activity::VoiceActivity;
use crate::claim::overlaps;
use crate::ledger::SAME_SPEECH_US;
use crate::transcript::{TranscriptMessage, vad_message};

/// The service that accepts transcripts for publication.
pub const SUBMIT: &str = agent_contract::channels::ASR_SUBMIT.name;
pub const TRANSCRIPT: &str = agent_contract::channels::TRANSCRIPT.name;
/// Where the transcripts of pauses go before the end of the turn is decided.
pub const PAUSE: &str = agent_contract::channels::TRANSCRIPT_PAUSE.name;

/// Takes the relay role whenever it is free, until the client shuts down; never, unless `take_role`.
pub async fn relay(
    client: Client,
    satellite: String,
    activity: broadcast::Sender<VoiceActivity>,
    take_role: bool,
) -> Result<(), SatelliteError> {
    if !take_role {
        tracing::info!(%satellite, "never relaying (--no-relay): transcripts go to the relay of {TRANSCRIPT}");
        return std::future::pending().await;
    }
    let mut events = client.events();
    loop {
        match client
            .publisher(TRANSCRIPT, agent_contract::channels::headers::TRANSCRIPT)
            .await
        {
            Ok(publisher) => {
                let mut service = match client.serve(SUBMIT, r#"{"mime":"application/json"}"#).await
                {
                    Ok(s) => s,
                    Err(e) => {
                        // Someone else's submit service is still there: give the role back.
                        tracing::warn!("could not serve {SUBMIT}: {e}");
                        drop(publisher);
                        wait_removed(&mut events, SUBMIT).await?;
                        continue;
                    }
                };
                // Previews of pauses go out beside the transcripts; a relay that cannot own their channel (a
                // previous holder's still there) relays transcripts without them.
                let previews = match client
                    .publisher(PAUSE, agent_contract::channels::headers::TRANSCRIPT)
                    .await
                {
                    Ok(previews) => Some(previews),
                    Err(e) => {
                        tracing::warn!("not publishing previews on {PAUSE}: {e}");
                        None
                    }
                };
                tracing::info!(%satellite, "relaying transcripts on {TRANSCRIPT}");
                // Only changes from now on: the previous holder published what came before.
                let mut changes = activity.subscribe();
                let mut published: VecDeque<(String, u64, u64)> = VecDeque::new();
                loop {
                    let call = tokio::select! {
                        call = service.next() => match call {
                            Some(call) => call,
                            None => break,
                        },
                        change = changes.recv() => {
                            match change {
                                Ok(change) => publish_activity(&publisher, &change, &satellite).await,
                                Err(broadcast::error::RecvError::Lagged(n)) => {
                                    tracing::warn!("{n} voice-activity changes not published (relay behind)");
                                }
                                // Cannot happen: this function holds a sender itself.
                                Err(broadcast::error::RecvError::Closed) => {}
                            }
                            continue;
                        }
                    };
                    let reply = match serde_json::from_slice::<TranscriptMessage>(&call.payload) {
                        Ok(t) if !t.is_final => {
                            publish_preview(previews.as_ref(), &call.payload).await
                        }
                        Ok(t) => {
                            let dup = published.iter().any(|(id, s, e)| {
                                *id == t.utterance
                                    || overlaps((*s, *e), (t.start_us, t.end_us), SAME_SPEECH_US)
                            });
                            if dup {
                                tracing::warn!(utterance = %t.utterance, "duplicate transcript not published");
                                Ok(bytes::Bytes::from_static(b"\"duplicate\""))
                            } else {
                                published.push_back((t.utterance.clone(), t.start_us, t.end_us));
                                while published.len() > 1024 {
                                    published.pop_front();
                                }
                                publisher
                                    .publish(bytes::Bytes::copy_from_slice(&call.payload))
                                    .await
                                    .map(|()| bytes::Bytes::from_static(b"\"published\""))
                                    .map_err(|e| e.to_string())
                            }
                        }
                        Err(e) => Err(format!("not a transcript: {e}")),
                    };
                    if let Err(e) = call.respond(reply).await {
                        tracing::warn!("answering a submission: {e}");
                    }
                }
                return Ok(());
            }
            Err(e) if e.code() == Some(ErrorCode::Exists) => {
                wait_removed(&mut events, TRANSCRIPT).await?
            }
            Err(e) => return Err(e.into()),
        }
    }
}

/// Publishes the transcript of a pause (not deduplicated: the final transcript of the same utterance follows).
async fn publish_preview(
    previews: Option<&Publisher>,
    payload: &[u8],
) -> Result<bytes::Bytes, String> {
    let Some(previews) = previews else {
        return Ok(bytes::Bytes::from_static(b"\"not relayed\""));
    };
    // A full lane drops the preview rather than hold up the submission: a late preview is worth nothing.
    match previews.try_publish(bytes::Bytes::copy_from_slice(payload)) {
        Ok(_) => Ok(bytes::Bytes::from_static(b"\"published\"")),
        Err(e) => Err(e.to_string()),
    }
}

/// Publishes one voice-activity change on `Agent.transcript`.
async fn publish_activity(publisher: &Publisher, change: &VoiceActivity, satellite: &str) {
    let message = vad_message(change, satellite);
    match serde_json::to_vec(&message) {
        Ok(payload) => {
            if let Err(e) = publisher.publish(bytes::Bytes::from(payload)).await {
                tracing::warn!("publishing voice activity: {e}");
            }
        }
        Err(e) => tracing::warn!("serialising voice activity: {e}"),
    }
}

async fn wait_removed(
    events: &mut tokio::sync::broadcast::Receiver<ClientEvent>,
    name: &str,
) -> Result<(), SatelliteError> {
    loop {
        match events.recv().await {
            Ok(ClientEvent::ChannelRemoved { name: n, .. }) if n == name => return Ok(()),
            // Missed events: the channel may be gone already, so try again.
            Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => return Ok(()),
            Err(e) => return Err(e.into()),
            Ok(_) => {}
        }
    }
}
