//! A service call's failure as it crosses hubs: the payload of a Zenoh error reply, JSON
//! `{"code":"ServiceGone","message":"..."}`, so that the calling hub can tell a vanished service from a failed one.

use flow::{ErrorCode, FlowError};
use serde::{Deserialize, Serialize};

/// Why the exporting hub could not answer a call.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RemoteError {
    /// The hub's error code by name (`ServiceGone`, `Timeout`, `Overloaded`, `ServiceFailed`...), or `Other`.
    pub code: String,
    pub message: String,
}

impl RemoteError {
    pub fn from_flow(e: &FlowError) -> RemoteError {
        let code = match e.code() {
            Some(c) => format!("{c:?}"),
            None => "Other".to_string(),
        };
        let message = match e {
            FlowError::Hub(reply) => reply.message.clone(),
            other => other.to_string(),
        };
        RemoteError { code, message }
    }

    /// Reads an error reply; a payload that is not ours (a plain Zenoh queryable) becomes its text.
    pub fn parse(bytes: &[u8]) -> RemoteError {
        serde_json::from_slice(bytes).unwrap_or_else(|_| RemoteError {
            code: "Other".into(),
            message: String::from_utf8_lossy(bytes).into_owned(),
        })
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }

    /// The service's owner left the exporting hub.
    pub fn is_gone(&self) -> bool {
        self.code == format!("{:?}", ErrorCode::ServiceGone)
    }
}

impl std::fmt::Display for RemoteError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({})", self.message, self.code)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use flow::protocol::ErrorReply;

    #[test]
    fn a_hub_refusal_keeps_its_code_across_hubs() {
        let e = FlowError::Hub(ErrorReply::new(ErrorCode::ServiceGone, "owner left"));
        let r = RemoteError::parse(RemoteError::from_flow(&e).to_json().as_bytes());
        assert!(r.is_gone());
        assert_eq!(r.message, "owner left");
        let t = RemoteError::from_flow(&FlowError::Timeout(std::time::Duration::from_secs(1)));
        assert_eq!(t.code, "Other");
        assert!(!t.is_gone());
    }

    #[test]
    fn a_foreign_error_payload_becomes_its_text() {
        let r = RemoteError::parse(b"no such thing");
        assert_eq!(r.code, "Other");
        assert_eq!(r.message, "no such thing");
    }
}
