//! The satellite's event loop: what it knows of the utterances, its peers and its claims, and what each input it
//! waits on (the segmenter, the decode in flight, the transcripts, the hub's events, a deadline) does to that.

use std::collections::{HashMap, HashSet, VecDeque};
use std::time::{Duration, Instant};

use bytes::Bytes;
use flow::{Client, ClientEvent, Publisher, Subscription};
use tokio::sync::{broadcast, mpsc};

use super::audio::{self, Heard};
use super::claiming::{finish, preview as preview_pause, transcript, try_claim};
use super::error::SatelliteError;
use super::settings::Settings;
use super::worker::{Decode, Finished, Held, Worker};
use crate::claim::{self, ClaimHeader, PRESENCE_PREFIX, PauseTurn};
use crate::ledger::{Ledger, Pending, SAME_SPEECH_US, Standing};
use crate::speculation::{Action, Hold};
use crate::stream::ClockedUtterance;
use crate::transcriber::{Outcome, TranscribeError, Transcriber};
use crate::transcript::TranscriptMessage;
use crate::turn::{self, Turn};

/// After a holder's claim vanishes, wait this long for its transcript before claiming the utterance again (the
/// transcript and the removal travel on different paths).
const RELEASE_GRACE: Duration = Duration::from_millis(400);
/// Delay per recent job before an idle satellite claims, when other satellites are present: the one that worked
/// least recently claims first, so consecutive utterances spread over the satellites.
const FAIRNESS_STEP: Duration = Duration::from_millis(150);
const FAIRNESS_WINDOW: Duration = Duration::from_secs(15);

/// What woke the satellite's loop: one variant per input it waits on.
enum Wake {
    /// The segmenter found, extended, resumed or abandoned an utterance (`None`: the segmenter stopped).
    Heard(Option<Heard>),
    /// The decode in flight came back with the transcriber (`None`: the blocking task panicked).
    Decoded(Option<(Transcriber, Decode)>),
    /// A transcript on `Agent.transcript` (`None`: the subscription ended).
    Transcript(Option<Bytes>),
    /// A hub event: channels coming and going, claims marked done, the connection's state.
    Hub(Result<ClientEvent, broadcast::error::RecvError>),
    /// A ledger deadline (a claim delay or a release grace) may have passed.
    Timer,
}

/// Whether the loop goes on after an event.
enum Next {
    Continue,
    Stop,
}

/// The satellite's state between events: what it knows of the utterances, its peers, its transcriber and its
/// claims. Each input the loop waits on has one method here.
pub(super) struct Satellite {
    client: Client,
    settings: Settings,
    model: String,
    /// Our own presence channel's name, which is not a peer.
    presence: String,
    listener: audio::Listener,
    /// The other satellites' presence channels: with none, nobody waits for fairness.
    peers: HashSet<String>,
    ledger: Ledger,
    worker: Worker,
    /// Finished claim channels, kept a while so late segmenters still see the utterance as taken.
    retained: VecDeque<(Instant, Publisher)>,
    /// When this satellite finished its recent utterances, for the fairness delay.
    recent_jobs: VecDeque<Instant>,
    /// The interval of every live claim channel (by name) whose header was seen: when one vanishes, the same speech
    /// under another id is released too (`Ledger::released`).
    claim_spans: HashMap<String, (u64, u64)>,
}

impl Satellite {
    /// A satellite that has just come up: it knows no utterances, holds no claim, and its transcriber is free.
    pub(super) fn new(
        client: Client,
        transcriber: Transcriber,
        settings: Settings,
        presence: String,
        listener: audio::Listener,
        peers: HashSet<String>,
    ) -> Self {
        Satellite {
            client,
            model: transcriber.model_name().to_owned(),
            presence,
            settings,
            listener,
            peers,
            // Generous: on a loaded machine a backlog may take minutes to clear, and losing speech is worse than
            // lateness.
            ledger: Ledger::new(Duration::from_secs(600)),
            worker: Worker {
                transcriber: Some(transcriber),
                ..Worker::default()
            },
            retained: VecDeque::new(),
            recent_jobs: VecDeque::new(),
            claim_spans: HashMap::new(),
        }
    }

    /// Waits on every input and handles each as it comes, until the segmenter, the transcripts or the hub events
    /// end, or Ctrl-C. Fails only when a decode task panicked.
    pub(super) async fn listen(
        &mut self,
        mut utterances: mpsc::Receiver<Heard>,
        transcripts: Subscription,
        mut events: broadcast::Receiver<ClientEvent>,
    ) -> Result<(), SatelliteError> {
        // Created once: a fresh `ctrl_c()` per turn of the loop would register with the signal driver again each
        // time.
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::pin!(ctrl_c);
        loop {
            let now = Instant::now();
            let claimed = self.claim_if_idle(now).await;
            self.expire(now);
            let wake = self.next_wake(now);

            let woke = tokio::select! {
                heard = utterances.recv() => Wake::Heard(heard),
                done = async { (&mut self.worker.decoding.as_mut()?.job).await.ok() }, if self.worker.decoding.is_some() => {
                    Wake::Decoded(done)
                }
                data = transcripts.recv() => Wake::Transcript(data.map(|d| d.payload)),
                event = events.recv() => Wake::Hub(event),
                () = tokio::time::sleep_until(wake.into()) => Wake::Timer,
                _ = &mut ctrl_c => break,
            };
            let finished = match woke {
                Wake::Heard(None) | Wake::Transcript(None) => break,
                Wake::Heard(Some(heard)) => self.on_heard(heard),
                Wake::Decoded(done) => self.on_decoded(done)?,
                Wake::Transcript(Some(payload)) => {
                    self.on_transcript(&payload);
                    None
                }
                Wake::Hub(event) => match self.on_hub(event) {
                    Next::Continue => None,
                    Next::Stop => break,
                },
                Wake::Timer => None,
            };
            self.announce_pause().await;
            // A claim finished by the decode it started and one finished by this event are both sent out.
            for f in [claimed, finished].into_iter().flatten() {
                self.on_finished(f).await;
            }
        }
        Ok(())
    }

    /// Claims the next claimable utterance when the worker is free; the decode it starts may finish at once.
    async fn claim_if_idle(&mut self, now: Instant) -> Option<Finished> {
        if !self.worker.idle() {
            return None;
        }
        let judge = self.settings.judge_turns;
        let (pending, claim, announced) = try_claim(
            &self.client,
            &mut self.ledger,
            &self.settings.name,
            judge,
            now,
        )
        .await?;
        let (hold, first) = Hold::claimed(pending.utterance, pending.ended);
        self.worker.held = Some(Held {
            hold,
            claim,
            verdict: None,
            pause: announced,
            announced,
        });
        self.act(Some(first))
    }

    /// Carries out what the hold asks and keeps the segmenter told about the end of the turn: a decode of a pause
    /// holds the end for its verdict, and a result of one gives the verdict (`crate::turn`).
    fn act(&mut self, action: Option<Action<Decode>>) -> Option<Finished> {
        if !self.settings.judge_turns {
            return self.worker.carry_out(action);
        }
        let Some(held) = self.worker.held.as_mut() else {
            return self.worker.carry_out(action);
        };
        let feed = match (&action, held.hold.paused_result()) {
            (Some(Action::Decode(u)), _) if !held.hold.is_ended() => {
                held.verdict = None;
                Some((u.clone(), None))
            }
            (None, Some(result)) => {
                let verdict = match result {
                    Ok(Outcome::Speech(d)) => turn::judge(&d.text),
                    Ok(Outcome::Rejected(..)) | Err(_) => Turn::Unknown,
                };
                tracing::debug!(id = %held.hold.id(), ?verdict, "end of turn judged");
                // The text the turn will have if it ends at this pause, out before the end is decided: the brain
                // may start a reply on it (docs/asr.md, "Previews").
                if let Ok(Outcome::Speech(d)) = result
                    && !held.hold.is_ended()
                {
                    let preview = TranscriptMessage {
                        is_final: false,
                        ..transcript(
                            held.hold.utterance(),
                            d,
                            &self.settings.name,
                            &self.model,
                            true,
                            Some(verdict),
                        )
                    };
                    preview_pause(&self.client, &preview);
                }
                held.verdict = Some(verdict);
                Some((held.hold.utterance().clone(), Some(verdict)))
            }
            _ => None,
        };
        if let Some((u, verdict)) = feed {
            held.pause = Some(PauseTurn {
                speech_end_us: u.speech_end_us,
                verdict,
                closed_us: None,
            });
            self.listener.send(audio::Feed::Turn {
                id: u.id,
                speech_end_us: u.speech_end_us,
                verdict,
            });
        }
        self.worker.carry_out(action)
    }

    /// Tells the other satellites, through the claim header, where the end of the turn stands at the pause this
    /// one decodes, so that their segmenters end the turn where ours does.
    async fn announce_pause(&mut self) {
        let Some(held) = self.worker.held.as_mut() else {
            return;
        };
        if held.pause == held.announced {
            return;
        }
        let u = held.hold.utterance();
        let header = ClaimHeader {
            pause: held.pause,
            ..ClaimHeader::new(u.start_us, u.speech_end_us, &self.settings.name, true)
        };
        match held.claim.set_header(&header.to_json()).await {
            Ok(()) => held.announced = held.pause,
            Err(e) => tracing::warn!(id = %u.id, "telling the others the end of the turn: {e}"),
        }
    }

    /// Another satellite's claim says where the end of its turn stands at a pause: our segmenter follows it.
    fn follow_pause(&self, id: &str, header: &ClaimHeader) {
        if !self.settings.judge_turns || header.done || header.satellite == self.settings.name {
            return;
        }
        match header.pause {
            Some(PauseTurn {
                speech_end_us,
                closed_us: Some(closed_us),
                ..
            }) => self.listener.send(audio::Feed::Ended {
                id: id.to_owned(),
                speech_end_us,
                closed_us,
            }),
            Some(p) => self.listener.send(audio::Feed::Turn {
                id: id.to_owned(),
                speech_end_us: p.speech_end_us,
                verdict: p.verdict,
            }),
            None => {}
        }
    }

    /// Lets go of retained claims and fairness marks that are old enough.
    fn expire(&mut self, now: Instant) {
        let retention = self.settings.claim_retention;
        while self
            .retained
            .front()
            .is_some_and(|(at, _)| now.duration_since(*at) > retention)
        {
            self.retained.pop_front();
        }
        while self
            .recent_jobs
            .front()
            .is_some_and(|at| now.duration_since(*at) > FAIRNESS_WINDOW)
        {
            self.recent_jobs.pop_front();
        }
    }

    /// When to look at the ledger again if nothing else happens: its next deadline while idle (a busy satellite
    /// claims nothing), else in a while anyway.
    fn next_wake(&self, now: Instant) -> Instant {
        self.ledger
            .next_deadline()
            .filter(|_| self.worker.idle())
            .unwrap_or(now + Duration::from_secs(5))
            .max(now + Duration::from_millis(5))
    }

    /// The segmenter's news: a held utterance goes to its hold, any other to the ledger.
    fn on_heard(&mut self, heard: Heard) -> Option<Finished> {
        // The wait for this event may have been long: fairness delays count from now.
        let now = Instant::now();
        let delay = if self.peers.is_empty() {
            Duration::ZERO
        } else {
            FAIRNESS_STEP * self.recent_jobs.len().min(4) as u32
        };
        let ended_here = match &heard {
            Heard::Ended(u) => self.ended_note(u),
            _ => None,
        };
        let action = match heard {
            Heard::Paused(u) => match self.worker.holding(&u.id) {
                Some(hold) => hold.paused(u),
                None => {
                    self.ledger.found(u, false, now, now + delay);
                    None
                }
            },
            Heard::Ended(u) => match self.worker.holding(&u.id) {
                Some(hold) => hold.ended(u),
                None => {
                    self.ledger.found(u, true, now, now + delay);
                    None
                }
            },
            Heard::Resumed { id } => match self.worker.holding(&id) {
                Some(hold) => hold.resumed(),
                None => {
                    self.ledger.resumed(&id);
                    None
                }
            },
            Heard::Abandoned { id } => return self.abandon(&id),
        };
        let mut finished = self.act(action);
        // The others hear of the end before the transcript goes out: with the claim finished at once, from
        // `on_finished`; else the loop writes it into the header now.
        if let Some(note) = ended_here {
            match (finished.as_mut(), self.worker.held.as_mut()) {
                (Some(f), _) => f.ended = Some(note),
                (None, Some(held)) => held.pause = Some(note),
                (None, None) => {}
            }
        }
        finished
    }

    /// What the claim header says of the held utterance `u` that our segmenter just ended: where it ended it, so
    /// that the other segmenters end it there too. Their ends could differ only because the holder alone judges
    /// the end of the turn, so without judging there is nothing to say.
    fn ended_note(&mut self, u: &ClockedUtterance) -> Option<PauseTurn> {
        if !self.settings.judge_turns || u.forced {
            return None;
        }
        let held = self.worker.held.as_ref().filter(|h| h.hold.id() == u.id)?;
        Some(PauseTurn {
            speech_end_us: u.speech_end_us,
            verdict: held
                .pause
                .filter(|p| p.speech_end_us == u.speech_end_us)
                .and_then(|p| p.verdict),
            closed_us: Some(u.closed_us),
        })
    }

    /// Recognition was switched off during utterance `id`: forget it, and if it is ours, stop decoding and finish
    /// the claim without a transcript.
    fn abandon(&mut self, id: &str) -> Option<Finished> {
        self.ledger.forget(id);
        self.worker.holding(id)?;
        let held = self.worker.held.take()?;
        if let Some(d) = &self.worker.decoding {
            d.abort.abort();
        }
        Some(Finished {
            claim: held.claim,
            utterance: held.hold.utterance().clone(),
            outcome: Err(TranscribeError::Aborted),
            speculative: false,
            turn: None,
            ended: None,
        })
    }

    /// Another satellite claimed the speech of the claim held here in the same instant, under another name (see
    /// `claim::yields_to`): if it keeps the speech, this satellite drops its claim (the channel goes) and its decode,
    /// so the speech is decoded once. Its utterance stays taken: the rival's claim overlaps it.
    fn yield_to_rival(&mut self, id: &str, header: &ClaimHeader) {
        let Some(held) = &self.worker.held else {
            return;
        };
        let ours = held.hold.utterance();
        if held.hold.id() == id
            || !claim::yields_to(
                &self.settings.name,
                (ours.start_us, ours.speech_end_us),
                header,
                SAME_SPEECH_US,
            )
        {
            return;
        }
        tracing::info!(
            ours = %held.hold.id(),
            theirs = %id,
            rival = %header.satellite,
            "the same speech was claimed by another satellite at once: leaving it to that one"
        );
        if let Some(d) = &self.worker.decoding {
            d.abort.abort();
        }
        // Back in the book as taken, by the rival's claim: should the rival die holding it, this satellite
        // claims the speech again (its claim's interval releases this entry).
        if let Some(held) = self.worker.held.take() {
            let pending = Pending {
                ended: held.hold.is_ended(),
                utterance: held.hold.utterance().clone(),
            };
            self.ledger
                .put_back(pending, Standing::Taken, Instant::now());
        }
    }

    /// The decode came back: the transcriber is free again, and the hold decides what the result is worth.
    fn on_decoded(
        &mut self,
        done: Option<(Transcriber, Decode)>,
    ) -> Result<Option<Finished>, SatelliteError> {
        self.worker.decoding = None;
        let Some((t, outcome)) = done else {
            return Err(SatelliteError::DecodePanicked);
        };
        self.worker.transcriber = Some(t);
        // Without a claim (abandoned meanwhile) the result is not wanted.
        let action = self
            .worker
            .held
            .as_mut()
            .and_then(|h| h.hold.decoded(outcome));
        Ok(self.act(action))
    }

    /// Someone's transcript: its utterance is done with.
    fn on_transcript(&mut self, payload: &[u8]) {
        if let Ok(t) = serde_json::from_slice::<TranscriptMessage>(payload) {
            self.ledger.finished(&t.utterance, t.start_us, t.end_us);
        }
    }

    /// A hub event: peers arriving and leaving, claims taken, released or marked done.
    fn on_hub(&mut self, event: Result<ClientEvent, broadcast::error::RecvError>) -> Next {
        match event {
            Ok(ClientEvent::ChannelAdded(info)) => {
                if info.name.starts_with(PRESENCE_PREFIX) && info.name != self.presence {
                    self.peers.insert(info.name);
                } else if let Some(id) = claim::claimed_utterance(&info.name) {
                    self.ledger.taken(id);
                    if let Some(header) = ClaimHeader::parse(&info.header) {
                        self.claim_spans
                            .insert(info.name.clone(), header.interval());
                        self.follow_pause(id, &header);
                        self.yield_to_rival(id, &header);
                    }
                }
            }
            Ok(ClientEvent::ChannelRemoved { name, .. }) => {
                self.peers.remove(&name);
                if name == agent_contract::channels::AUDIO.name
                    || name == agent_contract::channels::AUDIO_CLEAN.name
                {
                    self.listener.send(audio::Feed::Flush);
                }
                if let Some(id) = claim::claimed_utterance(&name) {
                    let span = self.claim_spans.remove(&name);
                    self.ledger
                        .released(id, span, Instant::now() + RELEASE_GRACE);
                }
            }
            Ok(ClientEvent::HeaderChanged { name, header, .. }) => {
                if let (Some(id), Some(claim)) =
                    (claim::claimed_utterance(&name), ClaimHeader::parse(&header))
                {
                    self.claim_spans.insert(name.clone(), claim.interval());
                    if claim.done {
                        let (start, end) = claim.interval();
                        self.ledger.finished(id, start, end);
                    } else {
                        self.follow_pause(id, &claim);
                    }
                }
            }
            Ok(ClientEvent::Disconnected(why)) => tracing::warn!("hub connection lost: {why}"),
            Ok(_) => {}
            Err(broadcast::error::RecvError::Lagged(n)) => tracing::warn!("missed {n} hub events"),
            Err(broadcast::error::RecvError::Closed) => return Next::Stop,
        }
        Next::Continue
    }

    /// Sends out what a finished claim produced, marks the claim done and keeps its channel a while.
    async fn on_finished(&mut self, f: Finished) {
        // Fairness counts the utterances a satellite finished; one abandoned unheard is no work done.
        if !matches!(f.outcome, Err(TranscribeError::Aborted)) {
            self.recent_jobs.push_back(Instant::now());
        }
        if let Some(note) = f.ended {
            let u = &f.utterance;
            let header = ClaimHeader {
                pause: Some(note),
                ..ClaimHeader::new(u.start_us, u.speech_end_us, &self.settings.name, true)
            };
            if let Err(e) = f.claim.set_header(&header.to_json()).await {
                tracing::warn!(id = %u.id, "telling the others where the utterance ended: {e}");
            }
        }
        finish(
            &self.client,
            &self.settings,
            &self.model,
            &f,
            &mut self.ledger,
        )
        .await;
        self.retained.push_back((Instant::now(), f.claim));
    }
}
