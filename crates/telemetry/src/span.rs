//! A finished span as the agent records it: a name, its place in the trace, its start and end on the Unix clock
//! (the hub clock every message carries) and a few attributes. Spans are written when their end is known, from
//! times the processes already keep, so no span object lives across a turn.

use crate::context::{SpanId, TraceContext};

/// An attribute's value.
#[derive(Debug, Clone, PartialEq)]
pub enum Attr {
    Text(String),
    Int(i64),
    Float(f64),
    Flag(bool),
}

impl From<&str> for Attr {
    fn from(v: &str) -> Self {
        Attr::Text(v.to_owned())
    }
}

impl From<String> for Attr {
    fn from(v: String) -> Self {
        Attr::Text(v)
    }
}

impl From<i64> for Attr {
    fn from(v: i64) -> Self {
        Attr::Int(v)
    }
}

impl From<u64> for Attr {
    fn from(v: u64) -> Self {
        Attr::Int(i64::try_from(v).unwrap_or(i64::MAX))
    }
}

impl From<u32> for Attr {
    fn from(v: u32) -> Self {
        Attr::Int(i64::from(v))
    }
}

impl From<f64> for Attr {
    fn from(v: f64) -> Self {
        Attr::Float(v)
    }
}

impl From<bool> for Attr {
    fn from(v: bool) -> Self {
        Attr::Flag(v)
    }
}

/// One finished span.
#[derive(Debug, Clone, PartialEq)]
pub struct SpanRecord {
    pub name: &'static str,
    /// Its trace and its own id.
    pub context: TraceContext,
    /// The span it belongs under; `None` for a trace's root.
    pub parent: Option<SpanId>,
    /// Microseconds since the Unix epoch.
    pub start_us: u64,
    pub end_us: u64,
    pub attributes: Vec<(&'static str, Attr)>,
}

impl SpanRecord {
    /// A root span from `start_us` to `end_us` (an end before the start is taken as the start).
    pub fn root(name: &'static str, context: TraceContext, start_us: u64, end_us: u64) -> Self {
        SpanRecord {
            name,
            context,
            parent: None,
            start_us,
            end_us: end_us.max(start_us),
            attributes: Vec::new(),
        }
    }

    /// A span under `parent`, with the id `parent.child(name)`: the one every process derives for that name.
    pub fn under(parent: TraceContext, name: &'static str, start_us: u64, end_us: u64) -> Self {
        Self::under_as(parent, name, name, start_us, end_us)
    }

    /// A span under `parent` whose id is derived from `key` rather than its name (several spans of one name: a
    /// sentence of a reply, a satellite's decode).
    pub fn under_as(
        parent: TraceContext,
        name: &'static str,
        key: &str,
        start_us: u64,
        end_us: u64,
    ) -> Self {
        SpanRecord {
            parent: Some(parent.span),
            ..Self::root(name, parent.child(key), start_us, end_us)
        }
    }

    /// Adds an attribute.
    pub fn with(mut self, key: &'static str, value: impl Into<Attr>) -> Self {
        self.attributes.push((key, value.into()));
        self
    }

    pub fn duration_us(&self) -> u64 {
        self.end_us - self.start_us
    }
}

/// Microseconds since the Unix epoch now (0 before 1970).
pub fn now_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_child_span_takes_its_parents_trace_and_the_id_every_process_derives() {
        let turn = TraceContext::turn("u7");
        let reply = SpanRecord::under(turn, "reply", 10, 30).with("sentences", 2u32);
        assert_eq!(reply.context, turn.child("reply"));
        assert_eq!(reply.parent, Some(turn.span));
        assert_eq!(reply.duration_us(), 20);
        assert_eq!(reply.attributes, vec![("sentences", Attr::Int(2))]);
        let second = SpanRecord::under_as(turn, "sentence", "sentence1", 0, 0);
        assert_eq!(second.context, turn.child("sentence1"));
    }

    #[test]
    fn an_end_before_its_start_makes_an_empty_span() {
        let s = SpanRecord::root("turn", TraceContext::turn("u1"), 50, 40);
        assert_eq!((s.start_us, s.end_us, s.duration_us()), (50, 50, 0));
    }
}
