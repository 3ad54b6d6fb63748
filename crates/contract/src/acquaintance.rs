//! Faces the agent was introduced to: the requests of `Agent.acquaintances` and what the pair database keeps of
//! each person (docs/vision.md, "Acquaintance"). Nothing is stored until a rule asks (`learn_face`), and only here:
//! a name and the face's 128-number descriptor, never a picture.

use serde::{Deserialize, Serialize};

/// The pair-database key of a person's entry is this prefix and their name in lower case.
pub const KEY_PREFIX: &str = "agent.faces.";

/// Names are at most this long (in characters).
pub const MAX_NAME_CHARS: usize = 40;

/// A request on `Agent.acquaintances`: `{"learn": "Anna"}` stores the face of the person talking (or of the only
/// face in view) under the name; `{"forget": true}` erases that face's entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AcquaintanceRequest {
    Learn(String),
    Forget(bool),
}

/// The answer: whose entry was stored or erased.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AcquaintanceAnswer {
    pub name: String,
    /// The person's id in `Agent.detections` (`people[].id`).
    pub person: u64,
    /// `learned` or `forgotten`.
    pub done: String,
}

/// One person's entry in the pair database, under [`key`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AcquaintanceRecord {
    pub name: String,
    /// dlib's face descriptor (128 numbers).
    pub descriptor: Vec<f32>,
    /// When it was stored (Unix milliseconds).
    pub learned_ms: i64,
}

/// The pair-database key of `name`'s entry.
pub fn key(name: &str) -> String {
    format!("{KEY_PREFIX}{}", name.to_lowercase())
}

/// The name as it is stored: trimmed, with a capital first letter; an error for an empty or overlong name, or one
/// with characters other than letters, digits, spaces, apostrophes and hyphens.
pub fn clean_name(name: &str) -> Result<String, String> {
    let name = name.trim().trim_end_matches(['.', '!', ',']);
    if name.is_empty() {
        return Err("the name is empty".into());
    }
    if name.chars().count() > MAX_NAME_CHARS {
        return Err(format!(
            "the name is longer than {MAX_NAME_CHARS} characters"
        ));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_alphanumeric() || matches!(c, ' ' | '\'' | '-')))
    {
        return Err(format!("the name has a {c:?}"));
    }
    let mut chars = name.chars();
    Ok(chars
        .next()
        .map(|first| first.to_uppercase().chain(chars).collect())
        .unwrap_or_default())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_read_as_documented() {
        let learn: AcquaintanceRequest =
            serde_json::from_str(r#"{"learn":"Anna"}"#).expect("learn");
        assert_eq!(learn, AcquaintanceRequest::Learn("Anna".into()));
        let forget: AcquaintanceRequest =
            serde_json::from_str(r#"{"forget":true}"#).expect("forget");
        assert_eq!(forget, AcquaintanceRequest::Forget(true));
        assert!(serde_json::from_str::<AcquaintanceRequest>(r#"{"remember":"x"}"#).is_err());
    }

    #[test]
    fn names_are_cleaned_or_refused() {
        assert_eq!(clean_name(" anna. "), Ok("Anna".into()));
        assert_eq!(clean_name("Jean-Luc"), Ok("Jean-Luc".into()));
        assert!(clean_name("").is_err());
        assert!(clean_name("a/b").is_err());
        assert!(clean_name(&"x".repeat(41)).is_err());
        assert_eq!(key("Anna"), "agent.faces.anna");
    }
}
