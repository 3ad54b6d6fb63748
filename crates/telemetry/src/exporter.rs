//! The process's span exporter: OTLP over HTTP with protobuf bodies (`opentelemetry-otlp`) behind the SDK's batch
//! processor, which queues spans (bounded, `OTEL_BSP_MAX_QUEUE_SIZE`, 2048 by default: a full queue drops the new
//! span) and sends them from a thread of its own every `OTEL_BSP_SCHEDULE_DELAY` (5 s). Off, a [`Telemetry`] is a
//! `None` that every call returns from at once: no thread, no queue, no allocation.

use std::borrow::Cow;
use std::sync::Arc;
use std::time::{Duration, UNIX_EPOCH};

use opentelemetry::trace::{SpanContext, SpanKind, Status, TraceFlags, TraceState};
use opentelemetry::{InstrumentationScope, KeyValue, Value};
use opentelemetry_otlp::{Protocol, WithExportConfig};
use opentelemetry_sdk::Resource;
use opentelemetry_sdk::error::OTelSdkResult;
use opentelemetry_sdk::trace::{
    BatchSpanProcessor, SpanData, SpanEvents, SpanExporter, SpanLinks, SpanProcessor,
};

use crate::settings::{SettingsError, traces_endpoint};
use crate::span::{Attr, SpanRecord};

/// How long the process waits at its end for the last spans to be sent.
const SHUTDOWN_WAIT: Duration = Duration::from_secs(2);
/// A collector that keeps failing is reported at most this often.
const FAILURE_REPORT: Duration = Duration::from_secs(60);

/// Why telemetry could not start.
#[derive(Debug, thiserror::Error)]
pub enum TelemetryError {
    #[error(transparent)]
    Settings(#[from] SettingsError),
    #[error("the OTLP exporter for {url}: {reason}")]
    Exporter { url: String, reason: String },
}

/// The process's telemetry: cheap to clone, shared by every part that records spans.
#[derive(Debug, Clone, Default)]
pub struct Telemetry {
    exporting: Option<Arc<Exporting>>,
}

#[derive(Debug)]
struct Exporting {
    processor: BatchSpanProcessor,
    scope: InstrumentationScope,
    url: String,
}

impl Telemetry {
    /// Telemetry that records nothing.
    pub fn off() -> Self {
        Telemetry::default()
    }

    /// Starts exporting as `service` (the `service.name` resource, unless `OTEL_SERVICE_NAME` names another) when
    /// a collector is named by `configured` (`(where the setting came from, its value)`) or the `OTEL_*`
    /// variables; off otherwise.
    pub fn start(service: &str, configured: Option<(&str, &str)>) -> Result<Self, TelemetryError> {
        let Some(url) = traces_endpoint(configured, |name| std::env::var(name).ok())? else {
            return Ok(Telemetry::off());
        };
        let exporter = opentelemetry_otlp::SpanExporter::builder()
            .with_http()
            .with_protocol(Protocol::HttpBinary)
            .with_endpoint(url.clone())
            .build()
            .map_err(|e| TelemetryError::Exporter {
                url: url.clone(),
                reason: e.to_string(),
            })?;
        let exporter = Reporting {
            inner: exporter,
            url: url.clone(),
            failures: flow::log::Throttle::new(FAILURE_REPORT),
        };
        let mut processor = BatchSpanProcessor::builder(exporter).build();
        let mut resource = Resource::builder();
        if std::env::var("OTEL_SERVICE_NAME").map_or(true, |v| v.trim().is_empty()) {
            resource = resource.with_service_name(service.to_owned());
        }
        processor.set_resource(&resource.build());
        let scope = InstrumentationScope::builder("robot-agent")
            .with_version(env!("CARGO_PKG_VERSION"))
            .build();
        tracing::info!(%url, "telemetry: exporting traces");
        Ok(Telemetry {
            exporting: Some(Arc::new(Exporting {
                processor,
                scope,
                url,
            })),
        })
    }

    pub fn is_on(&self) -> bool {
        self.exporting.is_some()
    }

    /// Queues a finished span for export; nothing when telemetry is off.
    pub fn record(&self, span: SpanRecord) {
        if let Some(e) = &self.exporting {
            e.processor.on_end(span_data(span, &e.scope));
        }
    }

    /// Sends what is queued now and waits for it (at most the exporter's timeout).
    pub fn flush(&self) {
        if let Some(e) = &self.exporting
            && let Err(error) = e.processor.force_flush()
        {
            tracing::warn!(url = %e.url, "telemetry: flushing spans: {error}");
        }
    }
}

impl Drop for Exporting {
    fn drop(&mut self) {
        if let Err(error) = self.processor.shutdown_with_timeout(SHUTDOWN_WAIT) {
            tracing::warn!(url = %self.url, "telemetry: the last spans were not all sent: {error}");
        }
    }
}

fn span_data(span: SpanRecord, scope: &InstrumentationScope) -> SpanData {
    let at = |us: u64| UNIX_EPOCH + Duration::from_micros(us);
    let context = SpanContext::new(
        opentelemetry::trace::TraceId::from_bytes(span.context.trace.0),
        opentelemetry::trace::SpanId::from_bytes(span.context.span.0),
        TraceFlags::SAMPLED,
        false,
        TraceState::NONE,
    );
    let parent = span
        .parent
        .map_or(opentelemetry::trace::SpanId::INVALID, |p| {
            opentelemetry::trace::SpanId::from_bytes(p.0)
        });
    SpanData {
        span_context: context,
        parent_span_id: parent,
        // Parents named by a message came from another process (or another part of this one): the spans of a
        // turn are joined by ids, never by an in-process parent object.
        parent_span_is_remote: span.parent.is_some(),
        span_kind: SpanKind::Internal,
        name: Cow::Borrowed(span.name),
        start_time: at(span.start_us),
        end_time: at(span.end_us),
        attributes: span
            .attributes
            .into_iter()
            .map(|(key, value)| KeyValue::new(key, value_of(value)))
            .collect(),
        dropped_attributes_count: 0,
        events: SpanEvents::default(),
        links: SpanLinks::default(),
        status: Status::Unset,
        instrumentation_scope: scope.clone(),
    }
}

fn value_of(attr: Attr) -> Value {
    match attr {
        Attr::Text(v) => Value::from(v),
        Attr::Int(v) => Value::from(v),
        Attr::Float(v) => Value::from(v),
        Attr::Flag(v) => Value::from(v),
    }
}

/// The OTLP exporter, with its failures logged (a collector that is down is one warning a minute, not one per
/// batch; the batch is dropped, as the SDK does).
#[derive(Debug)]
struct Reporting<E> {
    inner: E,
    url: String,
    failures: flow::log::Throttle,
}

impl<E: SpanExporter> SpanExporter for Reporting<E> {
    async fn export(&self, batch: Vec<SpanData>) -> OTelSdkResult {
        let spans = batch.len();
        let result = self.inner.export(batch).await;
        if let Err(error) = &result
            && let Some(left_out) = self.failures.admit()
        {
            tracing::warn!(url = %self.url, spans, "telemetry: spans not exported: {error}{left_out}");
        }
        result
    }

    fn shutdown_with_timeout(&self, timeout: Duration) -> OTelSdkResult {
        self.inner.shutdown_with_timeout(timeout)
    }

    fn force_flush(&self) -> OTelSdkResult {
        self.inner.force_flush()
    }

    fn set_resource(&mut self, resource: &Resource) {
        self.inner.set_resource(resource);
    }
}
