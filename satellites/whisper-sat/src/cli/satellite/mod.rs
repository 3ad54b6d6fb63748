//! The satellite: listens, claims utterances through the hub, transcribes them, submits transcripts.
//!
//! Every satellite segments the same `Agent.audio` stream and finds the same utterances. An idle satellite claims
//! the oldest utterance it knows by creating its claim channel (see `whisper_sat::claim`); the hub grants the name
//! to one. The holder transcribes, submits the transcript to the relay and marks its claim done in the claim's
//! header; the others drop the utterance when they see the transcript or the done mark. A holder that dies loses
//! its channels, the hub says so, and the others claim the utterance again. See docs/asr.md.
//!
//! With speculation (the default) utterances become claimable when they pause, before the hangover has ended them:
//! the holder decodes during the hangover and submits the result once the utterance ends unchanged, never before
//! (see `whisper_sat::speculation`). A claim stays with the holder when the voice resumes, since its id is the
//! utterance's start.

mod audio;
mod relay;

use audio::Heard;
use std::collections::{HashSet, VecDeque};
use std::time::{Duration, Instant};

use anyhow::Context;
use flow::{Client, ClientEvent, ErrorCode, Publisher};
use tokio::sync::watch;
use tokio::task::JoinHandle;
use whisper_sat::abort::AbortFlag;
use whisper_sat::claim::{self, CLAIM_PREFIX, PRESENCE_PREFIX};
use whisper_sat::ledger::{Ledger, Pending, Standing};
use whisper_sat::segmenter::SegmenterConfig;
use whisper_sat::speculation::{Action, Hold};
use whisper_sat::stream::ClockedUtterance;
use whisper_sat::transcriber::{Outcome, TranscribeError, Transcriber};
use whisper_sat::transcript::TranscriptMessage;

/// Settings of one satellite.
#[derive(Debug, Clone)]
pub struct Settings {
    pub name: String,
    pub segmenter: SegmenterConfig,
    /// How long a finished claim channel is kept, so late segmenters still see the utterance as taken.
    pub claim_retention: Duration,
    /// Claim and decode utterances when they pause, before the hangover ends them.
    pub speculate: bool,
}

/// After a holder's claim vanishes, wait this long for its transcript before claiming the utterance again (the
/// transcript and the removal travel on different paths).
const RELEASE_GRACE: Duration = Duration::from_millis(400);
/// Delay per recent job before an idle satellite claims, when other satellites are present: the one that worked
/// least recently claims first, so consecutive utterances spread over the satellites.
const FAIRNESS_STEP: Duration = Duration::from_millis(150);
const FAIRNESS_WINDOW: Duration = Duration::from_secs(15);
const SUBMIT_TIMEOUT: Duration = Duration::from_secs(5);

type Job = JoinHandle<(Transcriber, Result<Outcome, TranscribeError>)>;
type Decode = Result<Outcome, TranscribeError>;

/// The decode in flight and the flag that stops it.
struct Decoding {
    job: Job,
    abort: AbortFlag,
}

/// A claim this satellite holds and where its transcription stands.
struct Held {
    hold: Hold<Decode>,
    claim: Publisher,
}

/// A claim whose utterance is done with: its transcript (or why there is none) goes out and the claim is marked
/// done.
struct Finished {
    claim: Publisher,
    utterance: ClockedUtterance,
    outcome: Decode,
    speculative: bool,
}

/// The transcriber and its work: at most one claim held and at most one decode in flight. A decode can outlive
/// its claim (an abandoned utterance): the transcriber comes back with it either way.
#[derive(Default)]
struct Worker {
    transcriber: Option<Transcriber>,
    decoding: Option<Decoding>,
    held: Option<Held>,
}

impl Worker {
    /// Holds nothing and runs nothing: free to claim.
    fn idle(&self) -> bool {
        self.held.is_none() && self.decoding.is_none() && self.transcriber.is_some()
    }

    /// The held claim, when it is on utterance `id`.
    fn holding(&mut self, id: &str) -> Option<&mut Hold<Decode>> {
        self.held
            .as_mut()
            .map(|h| &mut h.hold)
            .filter(|h| h.id() == id)
    }

    /// Does what the hold asks; a submission is handed back to the caller, which owns the hub side.
    fn carry_out(&mut self, action: Option<Action<Decode>>) -> Option<Finished> {
        match action? {
            Action::Decode(utterance) => {
                let Some(mut t) = self.transcriber.take() else {
                    // The hold never asks for a second decode while one runs, so the transcriber is here.
                    tracing::error!(id = %utterance.id, "no transcriber free for a decode");
                    return None;
                };
                let abort = AbortFlag::new();
                let flag = abort.clone();
                let job = tokio::task::spawn_blocking(move || {
                    let outcome = t.transcribe_abortable(&utterance.audio, &flag);
                    (t, outcome)
                });
                self.decoding = Some(Decoding { job, abort });
                None
            }
            Action::Abort => {
                if let Some(d) = &self.decoding {
                    tracing::debug!("voice resumed: aborting the speculative decode");
                    d.abort.abort();
                }
                None
            }
            Action::Submit {
                utterance,
                result,
                speculative,
            } => self.held.take().map(|h| Finished {
                claim: h.claim,
                utterance,
                outcome: result,
                speculative,
            }),
        }
    }
}

/// Runs a satellite until the client closes or Ctrl-C.
pub async fn run(
    client: Client,
    transcriber: Transcriber,
    settings: Settings,
) -> anyhow::Result<()> {
    let presence = client
        .publisher(
            &format!("{PRESENCE_PREFIX}{}", settings.name),
            &serde_json::json!({ "model": transcriber.model_name(), "threads": transcriber.config().threads })
                .to_string(),
        )
        .await
        .context("creating the presence channel (is another satellite running with this --name?)")?;
    let (enabled_tx, enabled_rx) = watch::channel(true);
    let (listener, mut utterances) =
        audio::Listener::start(settings.segmenter.clone(), settings.speculate)?;
    let tasks = [
        tokio::spawn(audio::follow_ctrl(client.clone(), enabled_tx)),
        tokio::spawn(audio::follow_audio(
            client.clone(),
            listener.clone(),
            enabled_rx.clone(),
        )),
        tokio::spawn(relay::relay(
            client.clone(),
            settings.name.clone(),
            listener.activity.clone(),
        )),
    ];
    let transcripts = client.subscribe(relay::TRANSCRIPT).await?;
    let mut events = client.events();
    let mut peers: HashSet<String> = client
        .channels()
        .await?
        .into_iter()
        .filter(|c| c.name.starts_with(PRESENCE_PREFIX) && c.name != presence.name())
        .map(|c| c.name)
        .collect();

    // Generous: on a loaded machine a backlog may take minutes to clear, and losing speech is worse than lateness.
    let mut ledger = Ledger::new(Duration::from_secs(600));
    let model = transcriber.model_name().to_owned();
    let mut worker = Worker {
        transcriber: Some(transcriber),
        ..Worker::default()
    };
    let mut retained: VecDeque<(Instant, Publisher)> = VecDeque::new();
    let mut recent_jobs: VecDeque<Instant> = VecDeque::new();

    loop {
        let now = Instant::now();
        let mut finished = None;
        if worker.idle()
            && let Some((pending, claim)) =
                try_claim(&client, &mut ledger, &settings.name, now).await
        {
            let (hold, first) = Hold::claimed(pending.utterance, pending.ended);
            worker.held = Some(Held { hold, claim });
            finished = worker.carry_out(Some(first));
        }
        while retained
            .front()
            .is_some_and(|(at, _)| now.duration_since(*at) > settings.claim_retention)
        {
            retained.pop_front();
        }
        while recent_jobs
            .front()
            .is_some_and(|at| now.duration_since(*at) > FAIRNESS_WINDOW)
        {
            recent_jobs.pop_front();
        }
        let wake = ledger
            .next_deadline()
            .filter(|_| worker.idle())
            .unwrap_or(now + Duration::from_secs(5))
            .max(now + Duration::from_millis(5));

        tokio::select! {
            found = utterances.recv() => {
                let Some(heard) = found else { break };
                // The wait above may have been long: fairness delays count from now.
                let now = Instant::now();
                let delay = if peers.is_empty() { Duration::ZERO } else { FAIRNESS_STEP * recent_jobs.len().min(4) as u32 };
                let action = match heard {
                    Heard::Paused(u) => match worker.holding(&u.id) {
                        Some(hold) => hold.paused(u),
                        None => { ledger.found(u, false, now, now + delay); None }
                    },
                    Heard::Ended(u) => match worker.holding(&u.id) {
                        Some(hold) => hold.ended(u),
                        None => { ledger.found(u, true, now, now + delay); None }
                    },
                    Heard::Resumed { id } => match worker.holding(&id) {
                        Some(hold) => hold.resumed(),
                        None => { ledger.resumed(&id); None }
                    },
                    Heard::Abandoned { id } => {
                        ledger.forget(&id);
                        if worker.holding(&id).is_some() && let Some(h) = worker.held.take() {
                            if let Some(d) = &worker.decoding {
                                d.abort.abort();
                            }
                            finished = Some(Finished {
                                claim: h.claim,
                                utterance: h.hold.utterance().clone(),
                                outcome: Err(TranscribeError::Aborted),
                                speculative: false,
                            });
                        }
                        None
                    }
                };
                let submit = worker.carry_out(action);
                finished = finished.or(submit);
            }
            done = async { (&mut worker.decoding.as_mut()?.job).await.ok() }, if worker.decoding.is_some() => {
                worker.decoding = None;
                let Some((t, outcome)) = done else {
                    anyhow::bail!("the transcription task panicked");
                };
                worker.transcriber = Some(t);
                // Without a claim (abandoned meanwhile) the result is not wanted.
                let action = worker.held.as_mut().and_then(|h| h.hold.decoded(outcome));
                let submit = worker.carry_out(action);
                finished = finished.or(submit);
            }
            data = transcripts.recv() => {
                let Some(d) = data else { break };
                if let Ok(t) = serde_json::from_slice::<TranscriptMessage>(&d.payload) {
                    ledger.finished(&t.utterance, t.start_us, t.end_us);
                }
            }
            event = events.recv() => match event {
                Ok(ClientEvent::ChannelAdded(info)) if info.name.starts_with(PRESENCE_PREFIX) && info.name != presence.name() => {
                    peers.insert(info.name);
                }
                Ok(ClientEvent::ChannelAdded(info)) => {
                    if let Some(id) = claim::claimed_utterance(&info.name) {
                        ledger.taken(id);
                    }
                }
                Ok(ClientEvent::ChannelRemoved { name, .. }) => {
                    peers.remove(&name);
                    if name == "Agent.audio" {
                        listener.send(audio::Feed::Flush);
                    }
                    if let Some(id) = claim::claimed_utterance(&name) {
                        ledger.released(id, Instant::now() + RELEASE_GRACE);
                    }
                }
                Ok(ClientEvent::HeaderChanged { name, header, .. }) => {
                    if let (Some(id), Some((s, e))) = (claim::claimed_utterance(&name), claim::claim_interval(&header))
                        && header.contains("\"done\":true")
                    {
                        ledger.finished(id, s, e);
                    }
                }
                Ok(ClientEvent::Disconnected(why)) => tracing::warn!("hub connection lost: {why}"),
                Ok(_) => {}
                Err(tokio::sync::broadcast::error::RecvError::Lagged(n)) => tracing::warn!("missed {n} hub events"),
                Err(_) => break,
            },
            () = tokio::time::sleep_until(wake.into()) => {}
            _ = tokio::signal::ctrl_c() => break,
        }
        if let Some(f) = finished {
            // Fairness counts the utterances a satellite finished; one abandoned unheard is no work done.
            if !matches!(f.outcome, Err(TranscribeError::Aborted)) {
                recent_jobs.push_back(Instant::now());
            }
            finish(&client, &settings.name, &model, &f, &mut ledger).await;
            retained.push_back((Instant::now(), f.claim));
        }
    }
    for t in tasks {
        t.abort();
    }
    let dropped = listener.dropped.load(std::sync::atomic::Ordering::Relaxed);
    tracing::info!(dropped, "satellite stopped");
    drop(presence);
    Ok(())
}

/// Takes the next claimable utterance (paused or ended) and tries to claim it. Returns it with its claim channel on
/// success.
async fn try_claim(
    client: &Client,
    ledger: &mut Ledger,
    name: &str,
    now: Instant,
) -> Option<(Pending, Publisher)> {
    while let Some(p) = ledger.next_claimable(now) {
        let u = &p.utterance;
        // A satellite whose segmentation differs slightly names the same speech differently: an overlapping claim
        // by another name means it is taken too.
        let span = (u.start_us, u.speech_end_us);
        let overlapping = match client.channels().await {
            Ok(list) => list.into_iter().any(|c| {
                c.name.starts_with(CLAIM_PREFIX)
                    && claim::claimed_utterance(&c.name) != Some(u.id.as_str())
                    && claim::claim_interval(&c.header).is_some_and(|i| {
                        claim::overlaps(i, span, whisper_sat::ledger::SAME_SPEECH_US)
                    })
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
        let header = claim::claim_header(u.start_us, u.speech_end_us, name, !p.ended);
        match client
            .publisher(&claim::claim_channel(&u.id), &header)
            .await
        {
            Ok(claim) => {
                tracing::info!(id = %u.id, speculative = !p.ended, "claimed utterance");
                return Some((p, claim));
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
async fn finish(client: &Client, satellite: &str, model: &str, f: &Finished, ledger: &mut Ledger) {
    let u = &f.utterance;
    match &f.outcome {
        Ok(Outcome::Speech(d)) => {
            let msg = TranscriptMessage {
                utterance: u.id.clone(),
                text: d.text.clone(),
                start_us: u.start_us,
                end_us: u.speech_end_us,
                satellite: satellite.to_owned(),
                model: model.to_owned(),
                processing_ms: d.processing.as_millis() as u64,
                is_final: true,
                speculative: f.speculative,
                full_window_retry: d.full_window_retry,
            };
            tracing::info!(id = %u.id, ms = msg.processing_ms, speculative = f.speculative, text = %msg.text, "transcribed");
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
    let mut header: serde_json::Value = serde_json::from_str(&claim::claim_header(
        u.start_us,
        u.speech_end_us,
        satellite,
        f.speculative,
    ))
    .unwrap_or_default();
    header["done"] = serde_json::Value::Bool(true);
    if let Err(e) = f.claim.set_header(&header.to_string()).await {
        tracing::warn!(id = %u.id, "marking the claim done: {e}");
    }
}
