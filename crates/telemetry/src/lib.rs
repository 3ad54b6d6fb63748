//! OpenTelemetry traces of the agent's conversational turns (docs/telemetry.md): one trace per turn from the end of
//! the user's speech to the first audio of the reply, its spans recorded by each process that does the work
//! (robot-agent's stages, the rule, the synthesis; whisper-sat's decodes; llm-sat's generation) and joined by the
//! W3C trace context the turn's messages carry. Off unless a collector is named; off, recording costs a branch.

mod context;
mod exporter;
mod settings;
mod span;

pub use context::{ParseError, SpanId, TraceContext, TraceId};
pub use exporter::{Telemetry, TelemetryError};
pub use settings::{SettingsError, traces_endpoint};
pub use span::{Attr, SpanRecord, now_us};
