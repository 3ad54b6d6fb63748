//! The chat turns a language-model satellite (`llm-sat`) serves: the `Agent.chat` service (a turn in, the whole
//! reply out when it ends; or a cancel) and the `Agent.chat.reply` stream (the turn's prompt, its sentences as they
//! are generated, a tool call, its end). The brain's `chat(T)` action is the only caller (docs/llm.md).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// One chat turn handed to the model: what the user said, what the agent perceives now, the conversation so far
/// and the services the rule program lets the model call.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChatRequest {
    /// The brain's turn number; every event of the turn on `Agent.chat.reply` carries it.
    pub turn: u64,
    /// What the user said (the transcript).
    pub text: String,
    /// The language to answer in (`en`, `it`).
    pub language: String,
    /// What the agent perceives now, given to the model as data.
    pub facts: Facts,
    /// The conversation before this turn, oldest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub history: Vec<ChatMessage>,
    /// The services the model may call (the rule program's `tool` declarations).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tools: Vec<Tool>,
    /// The model must answer with a call of this tool (a rule's `chat(T, "Service")`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_tool: Option<String>,
    /// Started on the transcript of a pause before the end of the turn is decided: the satellite generates but
    /// publishes nothing until the same turn is asked for again without this flag, and drops it otherwise.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub speculative: bool,
    /// The agent's limits for this reply (`[modules.brain] chat_max_sentences`, `chat_timeout_ms`); the satellite
    /// applies the lower of these and its own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_sentences: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeout_ms: Option<u64>,
    /// The W3C `traceparent` of the reply span this turn's generation belongs under (docs/telemetry.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trace: Option<String>,
}

/// What the agent perceives when the turn starts. Texts read from the world (a code) are quoted as data in the
/// prompt, never given to the model as instructions.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Facts {
    /// Faces in view.
    pub faces: u32,
    /// Where the largest face is (`left`, `centre`, `right`), when there is one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face_where: Option<String>,
    /// Where the person talking is (`left`, `centre`, `right`), when the vision sees whose mouth moves.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speaker_where: Option<String>,
    /// The names of the faces in view that the agent was introduced to (`learn_face`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub names: Vec<String>,
    /// The text of a code seen in the last seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub code: Option<String>,
    /// Where something moves, when something does.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<String>,
    /// The local time and date, spoken.
    pub time: String,
    pub date: String,
    /// What the agent said last.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_said: Option<String>,
    /// Passages of the knowledge folder that match the question, best first (docs/knowledge.md): quoted as data,
    /// like a code's text, never given to the model as instructions.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub passages: Vec<Passage>,
}

/// A passage of the knowledge folder, with the file it came from (relative to the folder).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Passage {
    pub file: String,
    pub text: String,
}

/// Who said a line of the conversation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    User,
    Assistant,
}

/// One line of the conversation.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChatMessage {
    pub role: Role,
    pub text: String,
    /// The user talked over this reply (or stopped it): `text` is what they heard of it.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub interrupted: bool,
    /// A question: what the agent perceived when it was asked. The prompt gives a past question with its facts, as
    /// that turn did, so that the model's cache of that turn still holds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub facts: Option<Facts>,
    /// A reply heard whole: the text as the model wrote it (`text` is its spoken form), for the same reason.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generated: Option<String>,
}

/// A service the model may call: its arguments are text fields, each limited to the listed values.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tool {
    pub service: String,
    pub description: String,
    pub args: BTreeMap<String, Vec<String>>,
}

/// A call the model made: the service and the JSON object to call it with (the arguments of its [`Tool`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ToolCall {
    pub service: String,
    pub payload: serde_json::Value,
}

/// `{"cancel": TURN}`: stop generating that turn now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChatCancel {
    pub cancel: u64,
}

/// What `Agent.chat` takes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ChatCall {
    Cancel(ChatCancel),
    Turn(Box<ChatRequest>),
}

/// Why a reply ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Finish {
    /// The model ended it.
    Stop,
    /// It reached the configured number of sentences.
    Sentences,
    /// It reached the token limit.
    Tokens,
    /// It ran past the configured time.
    Timeout,
    /// A cancel (barge-in, `hush`) or a newer turn stopped it.
    Cancelled,
    /// The model answered with a tool call.
    Call,
}

/// The answer of `Agent.chat` to a turn, when the turn ends.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChatAnswer {
    pub turn: u64,
    /// The sentences published, joined.
    pub reply: String,
    /// The text as the model wrote it (before the spoken form), up to where it stopped.
    #[serde(default)]
    pub generated: String,
    pub sentences: u32,
    pub finish: Finish,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub call: Option<ToolCall>,
    pub stats: ChatStats,
}

/// What a turn cost.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChatStats {
    /// Tokens of the prompt, and how many of them came from the cache of the previous prompt.
    pub prompt_tokens: u32,
    pub cached_tokens: u32,
    /// Tokens generated.
    pub tokens: u32,
    /// From the request to the first generated token.
    pub first_token_ms: u64,
    /// From the request to the end.
    pub total_ms: u64,
    /// The turn was generated speculatively, before the end of the user's turn was decided.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub speculated: bool,
    /// A speculative turn nobody adopted (the final transcript differed, or was not handed to the model): what it
    /// generated is wasted work.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub dropped: bool,
}

/// One message on `Agent.chat.reply`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case", deny_unknown_fields)]
pub enum ChatEvent {
    /// The prompt the model is given (the rule trace shows it).
    Prompt {
        turn: u64,
        prompt: String,
        satellite: String,
        model: String,
    },
    /// One sentence of the reply, in order from 0, already in spoken form.
    Sentence { turn: u64, index: u32, text: String },
    /// The model called a tool.
    Call { turn: u64, call: ToolCall },
    /// The turn ended.
    End {
        turn: u64,
        finish: Finish,
        stats: ChatStats,
    },
}

impl ChatEvent {
    /// The turn the event belongs to.
    pub fn turn(&self) -> u64 {
        match self {
            ChatEvent::Prompt { turn, .. }
            | ChatEvent::Sentence { turn, .. }
            | ChatEvent::Call { turn, .. }
            | ChatEvent::End { turn, .. } => *turn,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cancel_and_a_turn_are_told_apart() {
        let cancel: ChatCall = serde_json::from_str(r#"{"cancel": 7}"#).expect("valid JSON");
        assert_eq!(cancel, ChatCall::Cancel(ChatCancel { cancel: 7 }));
        let turn: ChatCall = serde_json::from_str(
            r#"{"turn": 3, "text": "hi", "language": "en",
                "facts": {"faces": 1, "face_where": "left", "time": "ten past four", "date": "Saturday"}}"#,
        )
        .expect("valid JSON");
        let ChatCall::Turn(request) = turn else {
            panic!("not a turn: {turn:?}");
        };
        assert_eq!(request.turn, 3);
        assert_eq!(request.facts.face_where.as_deref(), Some("left"));
        assert!(request.history.is_empty() && !request.speculative);
    }

    #[test]
    fn a_request_with_an_unknown_field_is_refused() {
        let bad = serde_json::from_str::<ChatCall>(
            r#"{"turn": 3, "text": "hi", "language": "en", "facts": {"faces": 0, "time": "", "date": ""}, "x": 1}"#,
        );
        assert!(bad.is_err());
    }

    #[test]
    fn events_round_trip_with_their_tag() {
        let events = [
            ChatEvent::Prompt {
                turn: 1,
                prompt: "p".into(),
                satellite: "llm".into(),
                model: "m".into(),
            },
            ChatEvent::Sentence {
                turn: 1,
                index: 0,
                text: "Hello.".into(),
            },
            ChatEvent::Call {
                turn: 1,
                call: ToolCall {
                    service: "Robot.command".into(),
                    payload: serde_json::json!({"action": "turn"}),
                },
            },
            ChatEvent::End {
                turn: 1,
                finish: Finish::Stop,
                stats: ChatStats::default(),
            },
        ];
        for event in events {
            let json = serde_json::to_string(&event).expect("valid JSON");
            assert!(json.starts_with(r#"{"event":"#), "{json}");
            assert_eq!(
                serde_json::from_str::<ChatEvent>(&json).expect("valid JSON"),
                event
            );
        }
    }
}
