//! The brain's chat turns (`chat(T)`): one turn at a time handed to the language-model satellite over `Agent.chat`,
//! its sentences spoken as they arrive on `Agent.chat.reply`, stopped by a barge-in or `cancel`, and the
//! conversation kept in the pair database (forgotten after an idle time or by `forget_conversation`).

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use agent_contract::channels::CHAT;
use agent_contract::chat::{ChatAnswer, ChatEvent, ChatMessage, ChatRequest, Facts, Role, Tool};
use flow::Client;
use flow_telemetry::TraceContext;
use serde::{Deserialize, Serialize};
use tokio::sync::mpsc;
use tokio::time::Instant;
use tracing::{debug, info, warn};

use super::speech::Speech;
use super::turn::{Outcome, Said, Turn};

/// The limits of a reply, from the configuration.
#[derive(Debug, Clone, Copy)]
pub struct ChatLimits {
    pub max_sentences: u32,
    pub reply_timeout: Duration,
}

/// The pair-database key of the conversation.
pub const MEMORY_KEY: &str = "agent.chat.memory";

/// How long a cancel may take to reach the satellite.
const CANCEL_TIMEOUT: Duration = Duration::from_secs(2);

/// Finished calls waiting for the brain's loop (one per turn; turns are seconds apart).
pub const DONE_QUEUE: usize = 8;

/// The end of a turn's `Agent.chat` call.
#[derive(Debug)]
pub struct Done {
    pub turn: u64,
    pub result: Result<ChatAnswer, String>,
}

/// What the loop must do after a chat event or the end of a call.
#[derive(Debug, PartialEq)]
pub enum Next {
    /// Put a step in the rule trace.
    Trace {
        turn: u64,
        step: &'static str,
        text: String,
    },
    /// The model called a tool: perform the call (the rule program listed it).
    Call {
        turn: u64,
        service: String,
        payload: serde_json::Value,
    },
    /// The turn failed: assert `failed("chat", reason)`.
    Failed { turn: u64, reason: String },
}

/// The conversation as the pair database keeps it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
struct Memory {
    /// When the last turn ended (ms since the Unix epoch).
    updated_ms: i64,
    lines: Vec<ChatMessage>,
}

/// The brain's side of chat turns.
#[derive(Debug)]
pub struct Chats {
    client: Client,
    speech: Speech,
    done: mpsc::Sender<Done>,
    timeout: Duration,
    reply_timeout: Duration,
    max_sentences: u32,
    memory_turns: usize,
    forget_after: Duration,
    next_turn: u64,
    current: Option<Turn>,
    /// The sentences of the last finished turn, while they may still be playing: a barge-in then shortens the
    /// reply the memory keeps to what was heard.
    finished: Vec<Said>,
    memory: Memory,
    /// A reply started on the transcript of a pause, until the final transcript adopts or drops it.
    early: Option<Early>,
    /// The call that asked for the last speculative turn, until the satellite has it: the next turn's request waits
    /// for it, so that the satellite cannot take the real turn first and then see it superseded by the
    /// speculative one (a final transcript right after the pause's, on a loaded machine, did that: the real turn
    /// ended cancelled at once and the held reply was never adopted).
    speculating: Option<tokio::task::JoinHandle<()>>,
}

/// What a turn asks the model: the words, the language, the tools it may call (and the one it must), and what the
/// agent perceives.
#[derive(Debug, Clone, PartialEq)]
pub struct Ask {
    pub text: String,
    pub language: String,
    pub tools: Vec<Tool>,
    pub force_tool: Option<String>,
    pub facts: Facts,
}

impl Ask {
    /// The same question, whatever the facts said then: a speculative turn asked with these words is adopted with
    /// its own facts.
    fn same_words(&self, other: &Ask) -> bool {
        self.text == other.text
            && self.language == other.language
            && self.tools == other.tools
            && self.force_tool == other.force_tool
    }
}

/// A speculative turn: what it was asked with, so that the real turn asks for exactly the same and the satellite
/// adopts what it has generated (`llm_sat::satellite`, `same_turn`).
#[derive(Debug, Clone, PartialEq)]
struct Early {
    turn: u64,
    ask: Ask,
}

impl Chats {
    pub fn new(
        client: Client,
        speech: Speech,
        done: mpsc::Sender<Done>,
        limits: ChatLimits,
        memory_turns: usize,
        forget_after: Duration,
    ) -> Chats {
        Chats {
            client,
            speech,
            done,
            // The call outlives the reply's own limit by the time to say so.
            timeout: limits.reply_timeout + Duration::from_secs(5),
            reply_timeout: limits.reply_timeout,
            max_sentences: limits.max_sentences,
            memory_turns,
            forget_after,
            next_turn: unix_ms() as u64,
            current: None,
            finished: Vec::new(),
            memory: Memory::default(),
            early: None,
            speculating: None,
        }
    }

    /// Reads the conversation the pair database kept (a restart keeps it), unless it has been idle too long.
    pub async fn recall(&mut self) {
        match self.client.var_get(MEMORY_KEY).await {
            Ok(Some(value)) => match serde_json::from_value::<Memory>(value) {
                Ok(memory) if !self.stale(&memory) => {
                    info!(
                        lines = memory.lines.len(),
                        "brain: the conversation is recalled"
                    );
                    self.memory = memory;
                }
                Ok(_) => debug!("brain: the kept conversation is too old"),
                Err(e) => warn!("brain: {MEMORY_KEY} is not a conversation: {e}"),
            },
            Ok(None) => {}
            Err(e) => debug!("brain: reading {MEMORY_KEY} failed: {e}"),
        }
    }

    fn stale(&self, memory: &Memory) -> bool {
        unix_ms().saturating_sub(memory.updated_ms) > self.forget_after.as_millis() as i64
    }

    /// Forgets the conversation (`forget_conversation`).
    pub fn forget(&mut self) {
        self.memory = Memory::default();
        let client = self.client.clone();
        tokio::spawn(async move {
            if let Err(e) = client.var_del(MEMORY_KEY).await {
                debug!("brain: forgetting the conversation failed: {e}");
            }
        });
        info!("brain: the conversation is forgotten");
    }

    /// A turn is running and none of its reply has come yet (no sentence, no end, not interrupted).
    pub fn awaiting_reply(&self) -> bool {
        self.current
            .as_ref()
            .is_some_and(|t| t.said.is_empty() && t.interrupted.is_none() && !t.has_ended())
    }

    /// Starts a speculative turn on the transcript of a pause: the satellite generates and holds the reply back
    /// until [`Chats::start`] asks for the same turn. Nothing starts while a turn is running (a speculative request
    /// would cut it off). Returns its number.
    pub fn speculate(&mut self, ask: Ask) -> Option<u64> {
        if self.current.is_some() || self.early.as_ref().is_some_and(|e| e.ask.same_words(&ask)) {
            return None;
        }
        self.forget_if_stale();
        self.next_turn += 1;
        let early = Early {
            turn: self.next_turn,
            ask,
        };
        let request = self.request(&early, true, None);
        let turn = early.turn;
        self.early = Some(early);
        let client = self.client.clone();
        let body = serde_json::to_vec(&request).unwrap_or_default();
        self.speculating = Some(tokio::spawn(async move {
            // Answered at once (`{"speculating": true}`); the reply comes with the real turn.
            if let Err(e) = client.call(CHAT.name, body, CANCEL_TIMEOUT).await {
                debug!(turn, "brain: the speculative turn was not taken: {e}");
            }
        }));
        Some(turn)
    }

    /// The final transcript did not hand the speculative turn's text to the model: the satellite stops it.
    pub fn drop_early(&mut self) {
        if let Some(early) = self.early.take() {
            info!(turn = early.turn, "brain: the speculative reply is dropped");
            self.cancel(early.turn);
        }
    }

    /// A conversation idle longer than `forget_after` is not the one the next question continues.
    fn forget_if_stale(&mut self) {
        if self.stale(&self.memory) && !self.memory.lines.is_empty() {
            self.memory = Memory::default();
        }
    }

    /// The request of a turn, with the conversation as it stands.
    fn request(&self, turn: &Early, speculative: bool, reply: Option<TraceContext>) -> ChatRequest {
        let ask = &turn.ask;
        ChatRequest {
            turn: turn.turn,
            text: ask.text.clone(),
            language: ask.language.clone(),
            facts: ask.facts.clone(),
            history: self.memory.lines.clone(),
            tools: ask.tools.clone(),
            force_tool: ask.force_tool.clone(),
            speculative,
            max_sentences: Some(self.max_sentences),
            timeout_ms: Some(self.reply_timeout.as_millis() as u64),
            trace: reply.map(|r| r.traceparent()),
        }
    }

    fn cancel(&self, turn: u64) {
        let client = self.client.clone();
        let body = format!(r#"{{"cancel":{turn}}}"#);
        tokio::spawn(async move {
            if let Err(e) = client.call(CHAT.name, body, CANCEL_TIMEOUT).await {
                debug!(turn, "brain: cancelling the chat turn failed: {e}");
            }
        });
    }

    /// Starts a turn; one still running is cancelled first. A speculative turn on the same words is adopted (the
    /// request repeats its facts, so that the satellite keeps what it generated). Returns its number.
    pub fn start(&mut self, ask: Ask, reply: Option<TraceContext>) -> u64 {
        // A turn still running (or waiting for its answer) is cut off here: the memory keeps what was heard of it.
        self.interrupt(Instant::now());
        // (`interrupt` has just marked it, so its outcome is the interrupted reply without the model's text.)
        if let Some(old) = self.current.take() {
            self.remember(old.outcome());
        }
        self.forget_if_stale();
        self.next_turn += 1;
        let mut asked = Early {
            turn: self.next_turn,
            ask,
        };
        // Anything else speculated is superseded by this request at the satellite.
        if let Some(early) = self.early.take()
            && early.ask.same_words(&asked.ask)
        {
            debug!(
                early = early.turn,
                "brain: the turn adopts the speculative reply"
            );
            asked.ask.facts = early.ask.facts;
        }
        let turn = asked.turn;
        let request = self.request(&asked, false, reply);
        self.current = Some(Turn::new(turn, &asked.ask.text, asked.ask.facts));
        let (client, done, timeout) = (self.client.clone(), self.done.clone(), self.timeout);
        let body = serde_json::to_vec(&request).unwrap_or_default();
        let speculating = self.speculating.take();
        tokio::spawn(async move {
            // The speculative call is answered at once (or fails within CANCEL_TIMEOUT); how it ended does not
            // matter here, only that it reached the satellite first.
            if let Some(speculating) = speculating {
                let _ = speculating.await;
            }
            let result = match client.call(CHAT.name, body, timeout).await {
                Ok(answer) => serde_json::from_slice::<ChatAnswer>(&answer)
                    .map_err(|e| format!("the model's answer is malformed: {e}")),
                Err(e) => Err(e.to_string()),
            };
            // The queue holds a turn's end per turn; a full one means the loop is gone.
            let _ = done.send(Done { turn, result }).await;
        });
        turn
    }

    /// An event of `Agent.chat.reply`. `playout_end` is when the speech already queued ends.
    pub async fn event(&mut self, event: ChatEvent, playout_end: Option<Instant>) -> Vec<Next> {
        let Some(current) = self
            .current
            .as_mut()
            .filter(|t| t.turn == event.turn() && t.interrupted.is_none())
        else {
            return Vec::new();
        };
        match event {
            ChatEvent::Prompt { turn, prompt, .. } => vec![Next::Trace {
                turn,
                step: "prompt",
                text: prompt,
            }],
            ChatEvent::Sentence { turn, text, .. } => {
                // Queued in order on the speech task, behind anything the rules said before.
                self.speech.say(&text, false).await;
                current.said(text.clone(), playout_end.unwrap_or_else(Instant::now));
                let mut next = vec![Next::Trace {
                    turn,
                    step: "sentence",
                    text,
                }];
                next.extend(self.settle());
                next
            }
            // Performed unless the answer overtook the event and brought the call already.
            ChatEvent::Call { turn, call } => current
                .call_event(call)
                .map(|call| Next::Call {
                    turn,
                    service: call.service,
                    payload: call.payload,
                })
                .into_iter()
                .collect(),
            ChatEvent::End {
                turn,
                finish,
                stats,
            } => {
                current.end_event();
                let settled = self.settle();
                let mut next = vec![Next::Trace {
                    turn,
                    step: "end",
                    text: format!(
                        "{} after {} tokens, first token in {} ms{}",
                        serde_json::to_value(finish)
                            .ok()
                            .and_then(|v| v.as_str().map(str::to_owned))
                            .unwrap_or_default(),
                        stats.tokens,
                        stats.first_token_ms,
                        if stats.speculated { ", speculated" } else { "" }
                    ),
                }];
                next.extend(settled);
                next
            }
        }
    }

    /// The user spoke over the reply, or a rule cancelled speech: generation stops and the memory keeps what they
    /// heard. Returns the trace text when a turn was running.
    pub fn interrupt(&mut self, at: Instant) -> Option<(u64, String)> {
        let finished = std::mem::take(&mut self.finished);
        if self.current.is_none() && finished.iter().any(|s| s.starts > at) {
            let heard: Vec<String> = finished
                .iter()
                .filter(|s| s.starts <= at)
                .map(|s| s.text.clone())
                .collect();
            if let Some(last) = self.memory.lines.last_mut()
                && last.role == Role::Assistant
            {
                last.text = heard.join(" ");
                last.interrupted = true;
                last.generated = None;
                self.save();
            }
            return None;
        }
        let current = self.current.as_mut()?;
        if current.interrupted.is_some() {
            return None;
        }
        let heard: Vec<String> = current
            .said
            .iter()
            .filter(|s| s.starts <= at)
            .map(|s| s.text.clone())
            .collect();
        let turn = current.turn;
        current.interrupted = Some(heard.clone());
        self.cancel(turn);
        Some((turn, heard.join(" ")))
    }

    /// A turn's call ended. The answer may come before any event of its turn (it travels on the hub's control
    /// lane): a tool call it carries is performed from it then, and the late event adds nothing.
    pub fn done(&mut self, done: Done) -> Vec<Next> {
        let Some(current) = self.current.as_mut().filter(|t| t.turn == done.turn) else {
            return Vec::new();
        };
        match done.result {
            Ok(answer) => {
                let call = current.answered(answer).map(|call| Next::Call {
                    turn: done.turn,
                    service: call.service,
                    payload: call.payload,
                });
                let mut next: Vec<Next> = call.into_iter().collect();
                next.extend(self.settle());
                next
            }
            Err(reason) => {
                let interrupted = current.interrupted.is_some();
                self.current = None;
                // A turn the user interrupted may end with the satellite's error: nothing to apologise for.
                if interrupted {
                    Vec::new()
                } else {
                    vec![Next::Failed {
                        turn: done.turn,
                        reason,
                    }]
                }
            }
        }
    }

    /// Ends the running turn once its answer and its last sentence are both in: the memory keeps it. A turn that
    /// said nothing and called nothing, uninterrupted, fails rather than end in silence.
    fn settle(&mut self) -> Option<Next> {
        if !self.current.as_ref().is_some_and(Turn::settled) {
            return None;
        }
        let current = self.current.take()?;
        let turn = current.turn;
        let said = current.said.clone();
        let outcome = current.outcome();
        if !outcome.interrupted {
            self.finished = said;
        }
        let silent = outcome.silent;
        self.remember(outcome);
        silent.then(|| {
            warn!(
                turn,
                "brain: the chat turn ended with nothing said and nothing called"
            );
            Next::Failed {
                turn,
                reason: "the model gave no answer".into(),
            }
        })
    }

    fn remember(&mut self, outcome: Outcome) {
        let lines = &mut self.memory.lines;
        lines.push(ChatMessage {
            role: Role::User,
            text: outcome.question,
            interrupted: false,
            facts: Some(outcome.facts),
            generated: None,
        });
        lines.push(ChatMessage {
            role: Role::Assistant,
            text: outcome.reply,
            interrupted: outcome.interrupted,
            facts: None,
            generated: outcome.generated,
        });
        // Trimmed by half when full, not by one turn each time: the model's cache holds the prompt's prefix, and a
        // conversation that lost its oldest turn on every question would be evaluated again whole every time.
        let keep = self.memory_turns * 2;
        if lines.len() > keep {
            let half = (keep / 2).max(2);
            lines.drain(..lines.len() - half);
        }
        self.memory.updated_ms = unix_ms();
        self.save();
    }

    /// Writes the conversation to the pair database.
    fn save(&self) {
        let (client, value) = (
            self.client.clone(),
            serde_json::to_value(&self.memory).unwrap_or_default(),
        );
        tokio::spawn(async move {
            if let Err(e) = client.var_set(MEMORY_KEY, &value).await {
                warn!("brain: keeping the conversation failed: {e}");
            }
        });
    }

    /// Whether a turn is running (generating or speaking).
    pub fn running(&self) -> Option<u64> {
        self.current
            .as_ref()
            .filter(|t| t.interrupted.is_none())
            .map(|t| t.turn)
    }
}

fn unix_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}
