//! One chat turn's bookkeeping, without I/O: which of its pieces have come (sentences on `Agent.chat.reply`, the
//! tool call as an event or inside the call's answer, the `end` event, the answer itself), in whatever order the hub
//! delivers them, and whether it is settled. The answer travels on the hub's control lane and the events on the
//! stream's, so the answer may overtake every event of its turn: nothing here assumes an order.

use agent_contract::chat::{ChatAnswer, Facts, ToolCall};
use tokio::time::Instant;

/// A sentence sent to the TTS module, and when its audio should start.
#[derive(Debug, Clone)]
pub struct Said {
    pub text: String,
    pub starts: Instant,
}

/// How a settled turn ended, for the memory.
#[derive(Debug, PartialEq)]
pub struct Outcome {
    pub question: String,
    pub facts: Facts,
    /// What the user heard (or `(called Service)` for a turn that only called a tool).
    pub reply: String,
    /// The text as the model wrote it, for a reply heard whole.
    pub generated: Option<String>,
    pub interrupted: bool,
    /// Nothing was said and nothing called, and the user did not interrupt: the turn would end in silence.
    pub silent: bool,
}

/// The turn in progress.
#[derive(Debug)]
pub struct Turn {
    pub turn: u64,
    text: String,
    /// What the agent perceived when it was asked (kept with the question in the memory).
    facts: Facts,
    pub said: Vec<Said>,
    /// Set when the user interrupted it: what they heard of the reply.
    pub interrupted: Option<Vec<String>>,
    /// The `end` event came (on `Agent.chat.reply`, after every sentence).
    ended: bool,
    /// The call's answer came.
    answer: Option<ChatAnswer>,
    /// The service of the model's tool call, once handed on to be performed (from its event or from the answer,
    /// whichever came first): performed once, never lost, never twice.
    called: Option<String>,
}

impl Turn {
    /// Its `end` event or its call's answer came.
    pub fn has_ended(&self) -> bool {
        self.ended || self.answer.is_some()
    }

    pub fn new(turn: u64, text: &str, facts: Facts) -> Turn {
        Turn {
            turn,
            text: text.to_owned(),
            facts,
            said: Vec::new(),
            interrupted: None,
            ended: false,
            answer: None,
            called: None,
        }
    }

    /// A sentence of the reply was handed to the TTS module.
    pub fn said(&mut self, text: String, starts: Instant) {
        self.said.push(Said { text, starts });
    }

    /// The model's `call` event: the call to perform, unless the answer already brought it.
    pub fn call_event(&mut self, call: ToolCall) -> Option<ToolCall> {
        self.take_call(call)
    }

    /// The `end` event.
    pub fn end_event(&mut self) {
        self.ended = true;
    }

    /// The call's answer: the tool call it carries, when its event has not come yet (the answer overtook it).
    pub fn answered(&mut self, answer: ChatAnswer) -> Option<ToolCall> {
        let call = answer.call.clone();
        self.answer = Some(answer);
        call.and_then(|call| self.take_call(call))
    }

    fn take_call(&mut self, call: ToolCall) -> Option<ToolCall> {
        if self.called.is_some() || self.interrupted.is_some() {
            return None;
        }
        self.called = Some(call.service.clone());
        Some(call)
    }

    /// Whether the answer and every piece it counts are in: the `end` event, or the sentences it counts (a turn
    /// the user interrupted needs only the answer).
    pub fn settled(&self) -> bool {
        self.answer.as_ref().is_some_and(|answer| {
            self.ended || self.interrupted.is_some() || self.said.len() as u32 >= answer.sentences
        })
    }

    /// What the memory keeps of a settled (or cut-off) turn.
    pub fn outcome(self) -> Outcome {
        let (reply, interrupted) = match &self.interrupted {
            Some(heard) => (heard.join(" "), true),
            None => (
                self.said
                    .iter()
                    .map(|s| s.text.as_str())
                    .collect::<Vec<_>>()
                    .join(" "),
                false,
            ),
        };
        let generated = self
            .answer
            .map(|answer| answer.generated)
            .filter(|g| !g.is_empty());
        let silent = !interrupted && reply.is_empty() && self.called.is_none();
        let reply = match (self.called, reply.is_empty()) {
            (Some(service), true) => format!("(called {service})"),
            _ => reply,
        };
        Outcome {
            question: self.text,
            facts: self.facts,
            reply,
            generated: generated.filter(|_| !interrupted),
            interrupted,
            silent,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_contract::chat::{ChatStats, Finish};

    fn call() -> ToolCall {
        ToolCall {
            service: "Robot.command".into(),
            payload: serde_json::json!({"action": "turn", "direction": "left"}),
        }
    }

    fn answer(sentences: u32, call: Option<ToolCall>) -> ChatAnswer {
        ChatAnswer {
            turn: 1,
            reply: String::new(),
            generated: String::new(),
            sentences,
            finish: if call.is_some() {
                Finish::Call
            } else {
                Finish::Stop
            },
            call,
            stats: ChatStats::default(),
        }
    }

    /// The pieces of a turn that may come in any order.
    #[derive(Debug, Clone, Copy)]
    enum Piece {
        CallEvent,
        End,
        Answer,
    }

    fn permutations(pieces: &[Piece]) -> Vec<Vec<Piece>> {
        if pieces.len() <= 1 {
            return vec![pieces.to_vec()];
        }
        let mut all = Vec::new();
        for i in 0..pieces.len() {
            let mut rest = pieces.to_vec();
            let first = rest.remove(i);
            for mut tail in permutations(&rest) {
                tail.insert(0, first);
                all.push(tail);
            }
        }
        all
    }

    #[test]
    fn a_tool_call_is_handed_on_exactly_once_in_every_order_its_pieces_can_come() {
        let orders = permutations(&[Piece::CallEvent, Piece::End, Piece::Answer]);
        assert_eq!(orders.len(), 6);
        for order in orders {
            let mut turn = Turn::new(1, "Please face the window.", Facts::default());
            let mut performed = 0;
            let mut settled_at = None;
            for (i, piece) in order.iter().enumerate() {
                let handed = match piece {
                    Piece::CallEvent => turn.call_event(call()),
                    Piece::End => {
                        turn.end_event();
                        None
                    }
                    Piece::Answer => turn.answered(answer(0, Some(call()))),
                };
                performed += usize::from(handed.is_some());
                if settled_at.is_none() && turn.settled() {
                    settled_at = Some(i);
                }
            }
            assert_eq!(performed, 1, "order {order:?}");
            // The turn settles with its answer (a call-only turn counts no sentences), wherever the answer comes.
            let answer_at = order.iter().position(|p| matches!(p, Piece::Answer));
            assert_eq!(settled_at, answer_at, "order {order:?}");
            let outcome = turn.outcome();
            assert_eq!(outcome.reply, "(called Robot.command)");
            assert!(!outcome.silent);
        }
    }

    #[test]
    fn the_answer_that_overtakes_its_call_event_brings_the_call_itself() {
        // The lost call of issue 46: the answer (control lane) came first and settled the turn, and the call event
        // that came after found no turn. Now the answer hands the call on, and the late event adds nothing.
        let mut turn = Turn::new(1, "Please face the window.", Facts::default());
        assert_eq!(turn.answered(answer(0, Some(call()))), Some(call()));
        assert!(turn.settled());
        assert_eq!(turn.call_event(call()), None);
    }

    #[test]
    fn an_interrupted_turn_performs_no_call_that_comes_after_the_interruption() {
        let mut turn = Turn::new(1, "Please face the window.", Facts::default());
        turn.interrupted = Some(Vec::new());
        assert_eq!(turn.answered(answer(0, Some(call()))), None);
        assert_eq!(turn.call_event(call()), None);
        assert!(!turn.outcome().silent);
    }

    #[test]
    fn a_turn_waits_for_the_sentences_its_answer_counts() {
        let now = Instant::now();
        let mut turn = Turn::new(1, "Why is the sky blue?", Facts::default());
        assert_eq!(turn.answered(answer(2, None)), None);
        assert!(!turn.settled());
        turn.said("Sunlight scatters.".into(), now);
        assert!(!turn.settled());
        turn.said("Blue scatters most.".into(), now);
        assert!(turn.settled());
        let outcome = turn.outcome();
        assert_eq!(outcome.reply, "Sunlight scatters. Blue scatters most.");
        assert!(!outcome.silent);
    }

    #[test]
    fn a_turn_with_nothing_said_and_nothing_called_is_silent() {
        let mut turn = Turn::new(1, "Hm.", Facts::default());
        turn.end_event();
        assert_eq!(turn.answered(answer(0, None)), None);
        assert!(turn.settled());
        assert!(turn.outcome().silent);
    }
}
