//! The brain module's JSON edges: the `Agent.rules` trace message, the `Agent.speech` header and `Agent.avatar`
//! commands it reads, pair-database values, and the local time zone.

use agent_brain::{Trace, Value};
use agent_contract::avatar::AvatarCommand;
use agent_contract::rules::{ChatStep, RuleChange};

/// The `Agent.rules` message for one rule change: the fields the page shows (`ts_ms`, `program`, `rule`,
/// `action`, `because`) and the full trace for tools.
pub fn trace_message(trace: &Trace, origin: &str) -> Vec<u8> {
    let rule = rule_path(
        &trace
            .path
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>(),
    );
    let mut actions: Vec<String> = trace.effects.iter().map(ToString::to_string).collect();
    actions.extend(trace.updates.iter().cloned());
    let because: Vec<String> = trace
        .because
        .iter()
        .map(|evidence| evidence.fact.clone())
        .collect();
    let program = std::path::Path::new(origin)
        .file_name()
        .map_or(origin.into(), |name| name.to_string_lossy());
    let message = RuleChange {
        ts_ms: trace.unix_ms,
        program: program.into_owned(),
        rule,
        index: trace.path.last().map_or(0, |leaf| leaf.line),
        action: actions.join("; "),
        because,
        trace: serde_json::to_value(trace).unwrap_or_default(),
        interrupted: None,
        chat: None,
    };
    // Plain data with string keys always serialises.
    serde_json::to_vec(&message).unwrap_or_default()
}

/// A path of rules as `Agent.rules` shows it: `main.converse > answer.time`, or `(none)` when no rule holds.
pub fn rule_path(rules: &[String]) -> String {
    if rules.is_empty() {
        "(none)".to_owned()
    } else {
        rules.join(" > ")
    }
}

/// The `Agent.rules` entry a barge-in adds: `said` was cut off by the user speaking over it while `active`
/// (the brain's current rule path, as `trace_message` writes it) held.
pub fn interruption_message(unix_ms: i64, origin: &str, active: &str, said: &str) -> Vec<u8> {
    let program = std::path::Path::new(origin)
        .file_name()
        .map_or(origin.into(), |name| name.to_string_lossy());
    let message = RuleChange {
        ts_ms: unix_ms,
        program: program.into_owned(),
        rule: active.to_owned(),
        index: 0,
        action: format!("interrupted say({said:?})"),
        because: vec!["the user spoke over it".to_owned()],
        trace: serde_json::Value::Null,
        interrupted: Some(said.to_owned()),
        chat: None,
    };
    serde_json::to_vec(&message).unwrap_or_default()
}

/// The `Agent.rules` entry of one step of a chat turn, under the rule path `active`.
pub fn chat_message(unix_ms: i64, origin: &str, active: &str, step: ChatStep) -> Vec<u8> {
    let program = std::path::Path::new(origin)
        .file_name()
        .map_or(origin.into(), |name| name.to_string_lossy());
    let message = RuleChange {
        ts_ms: unix_ms,
        program: program.into_owned(),
        rule: active.to_owned(),
        index: 0,
        action: format!("chat {} {}: {}", step.turn, step.step, step.text),
        because: Vec::new(),
        trace: serde_json::Value::Null,
        interrupted: None,
        chat: Some(step),
    };
    serde_json::to_vec(&message).unwrap_or_default()
}

/// Whether `Agent.speech` payloads start with the 8-byte `[utterance u32][offset u32]` header, which its channel
/// header announces with a `framing` field (docs/browser-link.md).
pub fn speech_is_framed(header: &str) -> bool {
    serde_json::from_str::<serde_json::Value>(header)
        .is_ok_and(|header| header.get("framing").is_some())
}

/// Whether an `Agent.avatar` command is a barge-in `speech_stop`.
pub fn speech_stop(payload: &[u8]) -> Option<SpeechStop> {
    match serde_json::from_slice::<AvatarCommand>(payload).ok()? {
        AvatarCommand::SpeechStop { barge_in, .. } => Some(SpeechStop { barge_in }),
        _ => None,
    }
}

/// A `speech_stop` on `Agent.avatar`: speech was cancelled, or the user barged in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SpeechStop {
    pub barge_in: bool,
}

/// A pair-database value as the rule engine sees it (JSON `null` becomes an empty text).
pub fn value_from_json(value: serde_json::Value) -> Value {
    match value {
        serde_json::Value::Null => Value::Text(String::new()),
        serde_json::Value::Bool(b) => Value::Bool(b),
        serde_json::Value::Number(n) => Value::Num(n.as_f64().unwrap_or_default()),
        serde_json::Value::String(text) => Value::Text(text),
        serde_json::Value::Array(items) => {
            Value::List(items.into_iter().map(value_from_json).collect())
        }
        serde_json::Value::Object(map) => Value::Map(
            map.into_iter()
                .map(|(key, value)| (key, value_from_json(value)))
                .collect(),
        ),
    }
}

/// The server's local time zone, seconds east of UTC, for `time.*` in programs.
pub fn local_utc_offset_s() -> i32 {
    chrono::Local::now().offset().local_minus_utc()
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_brain::{Action, Effect, Evidence, RuleRef};
    use serde_json::json;

    #[test]
    fn the_trace_message_has_the_fields_the_page_shows() -> Result<(), serde_json::Error> {
        let trace = Trace {
            unix_ms: 1_700_000_000_000,
            path: vec![
                RuleRef {
                    procedure: "main".into(),
                    rule: "converse".into(),
                    line: 30,
                },
                RuleRef {
                    procedure: "answer".into(),
                    rule: "time".into(),
                    line: 48,
                },
            ],
            previous: vec![],
            reentered: false,
            because: vec![Evidence {
                fact: r#"heard("what time is it")"#.into(),
                age_ms: 3,
            }],
            bindings: vec![],
            effects: vec![Effect::Fire(Action::Say {
                text: "It is noon.".into(),
            })],
            updates: vec!["forget(heard)".into()],
        };
        let message: serde_json::Value =
            serde_json::from_slice(&trace_message(&trace, "config/brain.tr"))?;
        assert_eq!(message["ts_ms"], 1_700_000_000_000_i64);
        assert_eq!(message["program"], "brain.tr");
        assert_eq!(message["rule"], "main.converse > answer.time");
        assert_eq!(
            message["action"],
            r#"fire say("It is noon."); forget(heard)"#
        );
        assert_eq!(message["because"][0], r#"heard("what time is it")"#);
        assert_eq!(message["trace"]["path"][1]["line"], 48);
        Ok(())
    }

    #[test]
    fn speech_header_and_barge_in() {
        assert!(speech_is_framed(
            r#"{"rate":22050,"framing":"utterance-offset"}"#
        ));
        assert!(!speech_is_framed(r#"{"rate":22050}"#));
        assert_eq!(
            speech_stop(br#"{"cmd":"speech_stop","utterance":3}"#),
            Some(SpeechStop { barge_in: false })
        );
        assert_eq!(
            speech_stop(br#"{"cmd":"speech_stop","barge_in":true}"#),
            Some(SpeechStop { barge_in: true })
        );
        assert_eq!(
            speech_stop(br#"{"cmd":"blink","close_ms":1,"hold_ms":1,"open_ms":1}"#),
            None
        );
        assert_eq!(speech_stop(b"not json"), None);
    }

    #[test]
    fn pair_database_values() {
        let value =
            value_from_json(json!({"mode": "quiet", "level": 3, "on": true, "tags": ["a"]}));
        assert_eq!(
            value,
            Value::Map(vec![
                ("level".into(), Value::Num(3.0)),
                ("mode".into(), Value::from("quiet")),
                ("on".into(), Value::Bool(true)),
                ("tags".into(), Value::List(vec![Value::from("a")])),
            ])
        );
    }
}
