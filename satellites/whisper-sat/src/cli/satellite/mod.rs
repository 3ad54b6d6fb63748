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
use std::collections::{HashMap, HashSet, VecDeque};
use std::time::{Duration, Instant};

use anyhow::Context;
use bytes::Bytes;
use flow::{Client, ClientEvent, ErrorCode, Publisher};
use tokio::sync::{broadcast, watch};
use tokio::task::JoinHandle;
use whisper_sat::abort::AbortFlag;
use whisper_sat::claim::{self, CLAIM_PREFIX, ClaimHeader, PRESENCE_PREFIX, PauseTurn};
use whisper_sat::ledger::{Ledger, Pending, SAME_SPEECH_US, Standing};
use whisper_sat::segmenter::SegmenterConfig;
use whisper_sat::speculation::{Action, Hold};
use whisper_sat::stream::ClockedUtterance;
use whisper_sat::transcriber::{Outcome, TranscribeError, Transcriber};
use whisper_sat::transcript::TranscriptMessage;
use whisper_sat::turn::{self, Turn};

/// Settings of one satellite.
#[derive(Debug, Clone)]
pub struct Settings {
    pub name: String,
    pub segmenter: SegmenterConfig,
    /// How long a finished claim channel is kept, so late segmenters still see the utterance as taken.
    pub claim_retention: Duration,
    /// Claim and decode utterances when they pause, before the hangover ends them.
    pub speculate: bool,
    /// End an utterance early when the transcript of its pause reads as a complete turn, and hold it open longer
    /// when the transcript trails off (speculation only).
    pub judge_turns: bool,
    /// Hold the agent's own voice, heard back through loudspeakers, under a floor learned from `Agent.speech`
    /// (`whisper_sat::echo`).
    pub echo_gate: bool,
    /// Take the transcript relay role when it is free. Off for a satellite on a hub that imports the relay's
    /// channels from another hub (docs/federation.md): the relay lives there.
    pub relay: bool,
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
    /// The last verdict given on a pause of this utterance (it ended at that pause if it ended unchanged).
    verdict: Option<Turn>,
    /// Where the end of the turn stands at the pause being decoded, and what the claim header last told the
    /// other satellites of it: the loop writes the header when the two differ.
    pause: Option<PauseTurn>,
    announced: Option<PauseTurn>,
}

/// A claim whose utterance is done with: its transcript (or why there is none) goes out and the claim is marked
/// done.
struct Finished {
    claim: Publisher,
    utterance: ClockedUtterance,
    outcome: Decode,
    speculative: bool,
    /// The verdict on the pause the utterance ended at, if one was judged.
    turn: Option<Turn>,
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
                // A verdict is on a pause; an utterance that ended elsewhere (it resumed and ended unjudged) has none.
                turn: h.verdict.filter(|_| speculative),
                utterance,
                outcome: result,
                speculative,
            }),
        }
    }
}

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
struct Satellite {
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
    /// holds the end for its verdict, and a result of one gives the verdict (`whisper_sat::turn`).
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
                held.verdict = Some(verdict);
                Some((held.hold.utterance().clone(), Some(verdict)))
            }
            _ => None,
        };
        if let Some((u, verdict)) = feed {
            held.pause = Some(PauseTurn {
                speech_end_us: u.speech_end_us,
                verdict,
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
        if let Some(p) = header.pause {
            self.listener.send(audio::Feed::Turn {
                id: id.to_owned(),
                speech_end_us: p.speech_end_us,
                verdict: p.verdict,
            });
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
        self.act(action)
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
    ) -> anyhow::Result<Option<Finished>> {
        self.worker.decoding = None;
        let Some((t, outcome)) = done else {
            anyhow::bail!("the transcription task panicked");
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
                if name == agent_contract::channels::AUDIO.name {
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
        finish(
            &self.client,
            &self.settings.name,
            &self.model,
            &f,
            &mut self.ledger,
        )
        .await;
        self.retained.push_back((Instant::now(), f.claim));
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
        tokio::spawn(audio::follow_speech(
            client.clone(),
            listener.clone(),
            settings.echo_gate,
        )),
        tokio::spawn(relay::relay(
            client.clone(),
            settings.name.clone(),
            listener.activity.clone(),
            settings.relay,
        )),
    ];
    let transcripts = client.subscribe(relay::TRANSCRIPT).await?;
    let mut events = client.events();
    let peers: HashSet<String> = client
        .channels()
        .await?
        .into_iter()
        .filter(|c| c.name.starts_with(PRESENCE_PREFIX) && c.name != presence.name())
        .map(|c| c.name)
        .collect();

    let mut sat = Satellite {
        client: client.clone(),
        model: transcriber.model_name().to_owned(),
        presence: presence.name().to_owned(),
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
    };
    // Created once: a fresh `ctrl_c()` per turn of the loop would register with the signal driver again each time.
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);

    loop {
        let now = Instant::now();
        let claimed = sat.claim_if_idle(now).await;
        sat.expire(now);
        let wake = sat.next_wake(now);

        let woke = tokio::select! {
            heard = utterances.recv() => Wake::Heard(heard),
            done = async { (&mut sat.worker.decoding.as_mut()?.job).await.ok() }, if sat.worker.decoding.is_some() => {
                Wake::Decoded(done)
            }
            data = transcripts.recv() => Wake::Transcript(data.map(|d| d.payload)),
            event = events.recv() => Wake::Hub(event),
            () = tokio::time::sleep_until(wake.into()) => Wake::Timer,
            _ = &mut ctrl_c => break,
        };
        let finished = match woke {
            Wake::Heard(None) | Wake::Transcript(None) => break,
            Wake::Heard(Some(heard)) => sat.on_heard(heard),
            Wake::Decoded(done) => sat.on_decoded(done)?,
            Wake::Transcript(Some(payload)) => {
                sat.on_transcript(&payload);
                None
            }
            Wake::Hub(event) => match sat.on_hub(event) {
                Next::Continue => None,
                Next::Stop => break,
            },
            Wake::Timer => None,
        };
        sat.announce_pause().await;
        // A claim finished by the decode it started and one finished by this event are both sent out.
        for f in [claimed, finished].into_iter().flatten() {
            sat.on_finished(f).await;
        }
    }
    for t in tasks {
        t.abort();
    }
    let dropped = sat
        .listener
        .dropped
        .load(std::sync::atomic::Ordering::Relaxed);
    tracing::info!(dropped, "satellite stopped");
    drop(presence);
    Ok(())
}

/// Takes the next claimable utterance (paused or ended) and tries to claim it. Returns it with its claim channel on
/// success, and, when turns are judged and it is paused, the pause its header names as being decided.
async fn try_claim(
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
                    && ClaimHeader::parse(&c.header).is_some_and(|h| {
                        claim::overlaps(h.interval(), span, whisper_sat::ledger::SAME_SPEECH_US)
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
        // A paused utterance is claimed to decode that pause: the others hold their end of the turn for its
        // verdict from the moment they see the claim.
        let pause = (judge_turns && !p.ended).then_some(PauseTurn {
            speech_end_us: u.speech_end_us,
            verdict: None,
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
                turn: f.turn,
                threads: u32::try_from(d.threads).ok(),
            };
            tracing::info!(id = %u.id, ms = msg.processing_ms, threads = d.threads, speculative = f.speculative, turn = ?f.turn, text = %msg.text, "transcribed");
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
