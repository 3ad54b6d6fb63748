//! The hub side of a claim: taking an utterance by creating its claim channel, and finishing it by submitting the
//! transcript to the relay and marking the claim done in its header (`crate::claim` has the protocol).

use std::time::{Duration, Instant};

use flow::{Client, ErrorCode, Publisher};

use flow_telemetry::{SpanRecord, Telemetry, TraceContext, now_us};

use super::relay;
use super::settings::Settings;
use super::worker::Finished;
use crate::claim::{self, CLAIM_PREFIX, ClaimHeader, PauseTurn};
use crate::ledger::{Ledger, Pending, SAME_SPEECH_US, Standing};
use crate::stream::ClockedUtterance;
use crate::transcriber::{Decoded, Outcome, TranscribeError};
use crate::transcript::{TranscriptMessage, TurnVerdict};

/// How long one submission of a transcript waits for the relay's answer.
const SUBMIT_TIMEOUT: Duration = Duration::from_secs(5);
/// How long a pause's preview waits for the relay.
const PREVIEW_TIMEOUT: Duration = Duration::from_secs(1);

/// Takes the next claimable utterance (paused or ended) and tries to claim it. Returns it with its claim channel on
/// success, and, when turns are judged and it is paused, the pause its header names as being decided.
pub(super) async fn try_claim(
    client: &Client,
    ledger: &mut Ledger,
    name: &str,
    judge_turns: bool,
    now: Instant,
) -> Option<(Pending, Publisher, Option<PauseTurn>)> {
    while let Some(p) = ledger.next_claimable(now) {
        let u = &p.utterance;
        // A satellite whose segmentation differs slightly names the same speech differently: an overlapping claim
        // by another name means it is taken too.
        let span = (u.start_us, u.speech_end_us);
        let overlapping = match client.channels().await {
            Ok(list) => list.into_iter().any(|c| {
                c.name.starts_with(CLAIM_PREFIX)
                    && claim::claimed_utterance(&c.name) != Some(u.id.as_str())
                    && ClaimHeader::parse(&c.header)
                        .is_some_and(|h| claim::overlaps(h.interval(), span, SAME_SPEECH_US))
            }),
            Err(e) => {
                tracing::warn!("listing channels: {e}");
                ledger.put_back(p, Standing::Waiting, now + Duration::from_secs(1));
                return None;
            }
        };
        if overlapping {
            ledger.put_back(p, Standing::Taken, now);
            continue;
        }
        // A paused utterance is claimed to decode that pause: the others hold their end of the turn for its
        // verdict from the moment they see the claim.
        let pause = (judge_turns && !p.ended).then_some(PauseTurn {
            speech_end_us: u.speech_end_us,
            verdict: None,
            closed_us: None,
        });
        let header = ClaimHeader {
            pause,
            ..ClaimHeader::new(u.start_us, u.speech_end_us, name, !p.ended)
        }
        .to_json();
        match client
            .publisher(&claim::claim_channel(&u.id), &header)
            .await
        {
            Ok(claim) => {
                tracing::info!(id = %u.id, speculative = !p.ended, "claimed utterance");
                return Some((p, claim, pause));
            }
            Err(e) if e.code() == Some(ErrorCode::Exists) => {
                tracing::debug!(id = %u.id, "utterance taken by another satellite");
                ledger.put_back(p, Standing::Taken, now);
            }
            Err(e) => {
                tracing::warn!(id = %u.id, "claiming: {e}");
                let id = u.id.clone();
                ledger.put_back(p, Standing::Waiting, now);
                ledger.retry_later(&id, now + Duration::from_secs(1));
                return None;
            }
        }
    }
    None
}

/// Submits an accepted transcript (retrying while the relay role changes hands) and marks the claim done.
pub(super) async fn finish(
    client: &Client,
    settings: &Settings,
    model: &str,
    f: &Finished,
    ledger: &mut Ledger,
) {
    let satellite = settings.name.as_str();
    let u = &f.utterance;
    match &f.outcome {
        Ok(Outcome::Speech(d)) => {
            let turn = TraceContext::turn(&u.id);
            let msg = transcript(u, d, satellite, model, f.speculative, f.turn);
            record_decode(
                &settings.telemetry,
                turn,
                satellite,
                model,
                &msg,
                f.speculative,
            );
            tracing::info!(id = %u.id, trace_id = %turn.trace, ms = msg.processing_ms, threads = d.threads, speculative = f.speculative, turn = ?f.turn, text = %msg.text, "transcribed");
            let payload = serde_json::to_vec(&msg).unwrap_or_default();
            let deadline = Instant::now() + Duration::from_secs(15);
            loop {
                match client
                    .call(relay::SUBMIT, payload.clone(), SUBMIT_TIMEOUT)
                    .await
                {
                    Ok(_) => break,
                    Err(e) if Instant::now() < deadline => {
                        tracing::debug!("submitting transcript: {e}; retrying");
                        tokio::time::sleep(Duration::from_millis(200)).await;
                    }
                    Err(e) => {
                        tracing::error!(id = %u.id, "transcript lost: {e}");
                        break;
                    }
                }
            }
        }
        Ok(Outcome::Rejected(why, d)) => {
            tracing::info!(id = %u.id, ?why, text = %d.text, "no transcript: filtered as non-speech");
        }
        Err(TranscribeError::Aborted) => {
            tracing::info!(id = %u.id, "no transcript: recognition was switched off during the utterance");
        }
        Err(e) => tracing::error!(id = %u.id, "transcription failed: {e}"),
    }
    ledger.finished(&u.id, u.start_us, u.speech_end_us);
    let header = ClaimHeader {
        done: true,
        ..ClaimHeader::new(u.start_us, u.speech_end_us, satellite, f.speculative)
    };
    if let Err(e) = f.claim.set_header(&header.to_json()).await {
        tracing::warn!(id = %u.id, "marking the claim done: {e}");
    }
}

/// The transcript of `u` decoded as `d`, final; a pause's preview is the same with `is_final` false.
pub(super) fn transcript(
    u: &ClockedUtterance,
    d: &Decoded,
    satellite: &str,
    model: &str,
    speculative: bool,
    verdict: Option<TurnVerdict>,
) -> TranscriptMessage {
    TranscriptMessage {
        utterance: u.id.clone(),
        text: d.text.clone(),
        start_us: u.start_us,
        end_us: u.speech_end_us,
        satellite: satellite.to_owned(),
        model: model.to_owned(),
        processing_ms: d.processing.as_millis() as u64,
        is_final: true,
        speculative,
        full_window_retry: d.full_window_retry,
        turn: verdict,
        threads: u32::try_from(d.threads).ok(),
        trace: Some(TraceContext::turn(&u.id).traceparent()),
    }
}

/// Hands the transcript of a pause to the relay for `Agent.transcript.pause` (docs/asr.md, "Previews"), on a task of
/// its own so that the loop does not wait: one try, since a preview that comes late is worth nothing.
pub(super) fn preview(client: &Client, msg: &TranscriptMessage) {
    let payload = match serde_json::to_vec(msg) {
        Ok(payload) => payload,
        Err(e) => {
            tracing::warn!("serialising a preview: {e}");
            return;
        }
    };
    let client = client.clone();
    let id = msg.utterance.clone();
    tokio::spawn(async move {
        if let Err(e) = client.call(relay::SUBMIT, payload, PREVIEW_TIMEOUT).await {
            tracing::debug!(%id, "the pause's preview was not published: {e}");
        }
    });
}

/// The decode's span, under the turn's `transcription` stage (which robot-agent records from the hub's stamps): it
/// ends now, as the transcript goes to the relay, and began `processing_ms` before (at the pause when it was decoded
/// speculatively, so it may start before the stage does).
fn record_decode(
    telemetry: &Telemetry,
    turn: TraceContext,
    satellite: &str,
    model: &str,
    msg: &TranscriptMessage,
    speculative: bool,
) {
    if !telemetry.is_on() {
        return;
    }
    let end = now_us();
    let span = SpanRecord::under_as(
        turn.child("transcription"),
        "whisper.decode",
        &format!("decode {satellite}"),
        end.saturating_sub(msg.processing_ms.saturating_mul(1000)),
        end,
    )
    .with("satellite", satellite)
    .with("model", model)
    .with("utterance", msg.utterance.as_str())
    .with("audio_ms", msg.end_us.saturating_sub(msg.start_us) / 1000)
    .with("speculative", speculative);
    let span = match msg.threads {
        Some(threads) => span.with("threads", threads),
        None => span,
    };
    telemetry.record(span);
}
