//! A span's place in a trace, as W3C Trace Context writes it (`traceparent`), and the ids of one conversational
//! turn. The ids of a turn are derived from its utterance id, which every whisper satellite gives the same speech
//! (`u<start ms on the hub clock>`), and each stage's span id from the turn's: so every process that takes part in
//! a turn names the same spans without asking anyone, and the context that travels in the messages
//! (`TranscriptMessage.trace`, `ChatRequest.trace`, `SayRequest.trace`) tells it where it stands.
//!
//! ```text
//! traceparent = "00-" trace-id (32 hex) "-" parent-id (16 hex) "-" flags (2 hex)
//! ```
//! The flags are `01` (sampled): a turn is traced whole or not at all, and whether it is exported is the
//! exporting process's setting.

use std::fmt;

use sha2::{Digest, Sha256};

/// 16 bytes, never all zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TraceId(pub [u8; 16]);

/// 8 bytes, never all zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SpanId(pub [u8; 8]);

/// A span's trace and its own id: what a child names as its parent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TraceContext {
    pub trace: TraceId,
    pub span: SpanId,
}

/// Why a `traceparent` was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParseError {
    #[error("a traceparent has 4 fields separated by '-', this one {0}")]
    Fields(usize),
    #[error("unsupported traceparent version {0:?} (only 00)")]
    Version(String),
    #[error("the {field} is not {len} lowercase hex digits")]
    Hex { field: &'static str, len: usize },
    #[error("the {0} is all zeros")]
    Zero(&'static str),
}

impl TraceContext {
    /// The root span of the conversational turn whose speech has utterance id `utterance`.
    pub fn turn(utterance: &str) -> TraceContext {
        let digest = Sha256::new()
            .chain_update(b"robot-agent turn\0")
            .chain_update(utterance.as_bytes())
            .finalize();
        let mut trace = [0u8; 16];
        trace.copy_from_slice(&digest[..16]);
        let mut span = [0u8; 8];
        span.copy_from_slice(&digest[16..24]);
        TraceContext {
            trace: TraceId(nonzero(trace)),
            span: SpanId(nonzero(span)),
        }
    }

    /// The span named `name` under this one, in the same trace (the same name gives the same id).
    pub fn child(&self, name: &str) -> TraceContext {
        let digest = Sha256::new()
            .chain_update(self.span.0)
            .chain_update(b"\0")
            .chain_update(name.as_bytes())
            .finalize();
        let mut span = [0u8; 8];
        span.copy_from_slice(&digest[..8]);
        TraceContext {
            trace: self.trace,
            span: SpanId(nonzero(span)),
        }
    }

    /// `00-<trace>-<span>-01`.
    pub fn traceparent(&self) -> String {
        format!("00-{}-{}-01", self.trace, self.span)
    }

    /// Reads a `traceparent` header value.
    pub fn parse(traceparent: &str) -> Result<TraceContext, ParseError> {
        let fields: Vec<&str> = traceparent.trim().split('-').collect();
        let [version, trace, span, flags] = fields[..] else {
            return Err(ParseError::Fields(fields.len()));
        };
        if version != "00" {
            return Err(ParseError::Version(version.to_owned()));
        }
        let trace: [u8; 16] = hex(trace, "trace id")?;
        let span: [u8; 8] = hex(span, "parent id")?;
        let _: [u8; 1] = hex(flags, "flags")?;
        if trace == [0; 16] {
            return Err(ParseError::Zero("trace id"));
        }
        if span == [0; 8] {
            return Err(ParseError::Zero("parent id"));
        }
        Ok(TraceContext {
            trace: TraceId(trace),
            span: SpanId(span),
        })
    }
}

/// An id that happened to hash to zeros (invalid in W3C Trace Context) gets its last bit set.
fn nonzero<const N: usize>(mut id: [u8; N]) -> [u8; N] {
    if id.iter().all(|b| *b == 0) {
        id[N - 1] = 1;
    }
    id
}

fn hex<const N: usize>(text: &str, field: &'static str) -> Result<[u8; N], ParseError> {
    let wrong = ParseError::Hex { field, len: N * 2 };
    let digits = text.as_bytes();
    if digits.len() != N * 2 {
        return Err(wrong);
    }
    let value = |d: u8| match d {
        b'0'..=b'9' => Some(d - b'0'),
        b'a'..=b'f' => Some(d - b'a' + 10),
        _ => None,
    };
    let mut out = [0u8; N];
    for (i, pair) in digits.chunks_exact(2).enumerate() {
        match (value(pair[0]), value(pair[1])) {
            (Some(hi), Some(lo)) => out[i] = hi << 4 | lo,
            _ => return Err(wrong),
        }
    }
    Ok(out)
}

impl fmt::Display for TraceId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.iter().try_for_each(|b| write!(f, "{b:02x}"))
    }
}

impl fmt::Display for SpanId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.iter().try_for_each(|b| write!(f, "{b:02x}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_traceparent_round_trips() -> Result<(), ParseError> {
        let turn = TraceContext::turn("u1765012345678");
        let text = turn.traceparent();
        assert_eq!(text.len(), 55);
        assert!(text.starts_with("00-") && text.ends_with("-01"));
        assert_eq!(TraceContext::parse(&text)?, turn);
        Ok(())
    }

    #[test]
    fn the_w3c_example_parses() -> Result<(), ParseError> {
        let c = TraceContext::parse("00-0af7651916cd43dd8448eb211c80319c-b7ad6b7169203331-01")?;
        assert_eq!(c.trace.to_string(), "0af7651916cd43dd8448eb211c80319c");
        assert_eq!(c.span.to_string(), "b7ad6b7169203331");
        Ok(())
    }

    #[test]
    fn malformed_traceparents_are_refused_with_their_reason() {
        let ok_trace = "0af7651916cd43dd8448eb211c80319c";
        let cases = [
            (String::new(), ParseError::Fields(1)),
            ("00-abc".to_owned(), ParseError::Fields(2)),
            (
                format!("01-{ok_trace}-b7ad6b7169203331-01"),
                ParseError::Version("01".into()),
            ),
            (
                format!("00-{}-b7ad6b7169203331-01", ok_trace.to_uppercase()),
                ParseError::Hex {
                    field: "trace id",
                    len: 32,
                },
            ),
            (
                format!("00-{ok_trace}-b7ad6b71692033-01"),
                ParseError::Hex {
                    field: "parent id",
                    len: 16,
                },
            ),
            (
                format!("00-{ok_trace}-b7ad6b7169203331-1"),
                ParseError::Hex {
                    field: "flags",
                    len: 2,
                },
            ),
            (
                format!("00-{}-b7ad6b7169203331-01", "0".repeat(32)),
                ParseError::Zero("trace id"),
            ),
            (
                format!("00-{ok_trace}-0000000000000000-01"),
                ParseError::Zero("parent id"),
            ),
            (
                format!("00-{ok_trace}-b7ad6b7169203331-01-extra"),
                ParseError::Fields(5),
            ),
        ];
        for (text, error) in cases {
            assert_eq!(TraceContext::parse(&text), Err(error), "{text:?}");
        }
    }

    #[test]
    fn every_process_derives_the_same_ids_for_one_turn_and_different_ids_for_another() {
        let a = TraceContext::turn("u1000");
        assert_eq!(a, TraceContext::turn("u1000"));
        assert_eq!(a.child("reply"), TraceContext::turn("u1000").child("reply"));
        let b = TraceContext::turn("u1001");
        assert_ne!(a.trace, b.trace);
        let (reply, rule) = (a.child("reply"), a.child("rule"));
        assert_eq!(reply.trace, a.trace, "a child stays in its trace");
        assert_ne!(reply.span, rule.span);
        assert_ne!(reply.span, a.span);
        assert_ne!(reply.child("llm").span, rule.child("llm").span);
    }

    #[test]
    fn random_contexts_round_trip_through_their_text() -> Result<(), ParseError> {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..500 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let c = TraceContext::turn(&format!("u{seed}")).child(&seed.to_string());
            assert_eq!(TraceContext::parse(&c.traceparent())?, c);
        }
        Ok(())
    }
}
