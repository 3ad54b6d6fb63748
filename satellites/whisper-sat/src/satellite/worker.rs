//! The claim/decode worker: the satellite's one transcriber, the claim it holds and the decode in flight.
//!
//! The worker carries out what the claim's hold (`crate::speculation::Hold`) asks: start a decode on a blocking
//! thread, abort it when the voice resumes, or hand back the finished claim for the event loop to send out. It owns
//! no hub side: claims are taken and finished by `claiming`.

use flow::Publisher;
use tokio::task::JoinHandle;

use crate::abort::AbortFlag;
use crate::claim::PauseTurn;
use crate::speculation::{Action, Hold};
use crate::stream::ClockedUtterance;
use crate::transcriber::{Outcome, TranscribeError, Transcriber};
use crate::turn::Turn;

pub(super) type Job = JoinHandle<(Transcriber, Result<Outcome, TranscribeError>)>;
pub(super) type Decode = Result<Outcome, TranscribeError>;

/// The decode in flight and the flag that stops it.
pub(super) struct Decoding {
    pub(super) job: Job,
    pub(super) abort: AbortFlag,
}

/// A claim this satellite holds and where its transcription stands.
pub(super) struct Held {
    pub(super) hold: Hold<Decode>,
    pub(super) claim: Publisher,
    /// The last verdict given on a pause of this utterance (it ended at that pause if it ended unchanged).
    pub(super) verdict: Option<Turn>,
    /// Where the end of the turn stands at the pause being decoded, and what the claim header last told the
    /// other satellites of it: the loop writes the header when the two differ.
    pub(super) pause: Option<PauseTurn>,
    pub(super) announced: Option<PauseTurn>,
}

/// A claim whose utterance is done with: its transcript (or why there is none) goes out and the claim is marked
/// done.
pub(super) struct Finished {
    pub(super) claim: Publisher,
    pub(super) utterance: ClockedUtterance,
    pub(super) outcome: Decode,
    pub(super) speculative: bool,
    /// The verdict on the pause the utterance ended at, if one was judged.
    pub(super) turn: Option<Turn>,
    /// Where our segmenter ended the utterance, for the claim header before the transcript goes out
    /// (`Satellite::ended_note`).
    pub(super) ended: Option<PauseTurn>,
}

/// The transcriber and its work: at most one claim held and at most one decode in flight. A decode can outlive
/// its claim (an abandoned utterance): the transcriber comes back with it either way.
#[derive(Default)]
pub(super) struct Worker {
    pub(super) transcriber: Option<Transcriber>,
    pub(super) decoding: Option<Decoding>,
    pub(super) held: Option<Held>,
}

impl Worker {
    /// Holds nothing and runs nothing: free to claim.
    pub(super) fn idle(&self) -> bool {
        self.held.is_none() && self.decoding.is_none() && self.transcriber.is_some()
    }

    /// The held claim, when it is on utterance `id`.
    pub(super) fn holding(&mut self, id: &str) -> Option<&mut Hold<Decode>> {
        self.held
            .as_mut()
            .map(|h| &mut h.hold)
            .filter(|h| h.id() == id)
    }

    /// Does what the hold asks; a submission is handed back to the caller, which owns the hub side.
    pub(super) fn carry_out(&mut self, action: Option<Action<Decode>>) -> Option<Finished> {
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
                ended: None,
            }),
        }
    }
}
