//! A test OpenTelemetry collector: an HTTP/1.1 server on a loopback port that takes OTLP/HTTP protobuf exports at
//! `/v1/traces`, decodes them with OpenTelemetry's own protobuf definitions (`opentelemetry-proto`) and hands every
//! span over with the `service.name` of the process that sent it.

use std::convert::Infallible;
use std::net::SocketAddr;
use std::time::Duration;

use bytes::Bytes;
use http_body_util::{BodyExt, Full};
use hyper::body::Incoming;
use hyper::{Request, Response, StatusCode};
use opentelemetry_proto::tonic::collector::trace::v1::ExportTraceServiceRequest;
use opentelemetry_proto::tonic::common::v1::any_value::Value;
use opentelemetry_proto::tonic::trace::v1::Span;
use prost::Message;
use tokio::net::TcpListener;
use tokio::sync::mpsc;

/// Spans buffered before the receiver answers exporters with 503 (they then drop the batch: a test that reads
/// nothing fails on what it did not read, never hangs an exporter).
const QUEUE: usize = 4096;

/// A span as it arrived, with the service that exported it.
#[derive(Debug, Clone)]
pub struct Received {
    pub service: String,
    pub span: Span,
}

impl Received {
    pub fn trace_id(&self) -> String {
        hex(&self.span.trace_id)
    }
    pub fn span_id(&self) -> String {
        hex(&self.span.span_id)
    }
    pub fn parent_id(&self) -> String {
        hex(&self.span.parent_span_id)
    }
    pub fn start_ns(&self) -> u64 {
        self.span.start_time_unix_nano
    }
    pub fn end_ns(&self) -> u64 {
        self.span.end_time_unix_nano
    }
    pub fn duration_ms(&self) -> f64 {
        self.end_ns().saturating_sub(self.start_ns()) as f64 / 1e6
    }
    /// A string or integer attribute, as text.
    pub fn attribute(&self, key: &str) -> Option<String> {
        let kv = self.span.attributes.iter().find(|kv| kv.key == key)?;
        match kv.value.as_ref()?.value.as_ref()? {
            Value::StringValue(s) => Some(s.clone()),
            Value::IntValue(i) => Some(i.to_string()),
            Value::BoolValue(b) => Some(b.to_string()),
            Value::DoubleValue(d) => Some(d.to_string()),
            _ => None,
        }
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The receiver: its address, and the spans as they come.
#[derive(Debug)]
pub struct Collector {
    pub addr: SocketAddr,
    spans: mpsc::Receiver<Received>,
    task: tokio::task::JoinHandle<()>,
}

impl Drop for Collector {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl Collector {
    /// Listens on a free loopback port.
    pub async fn start() -> anyhow::Result<Collector> {
        let listener = TcpListener::bind("127.0.0.1:0").await?;
        let addr = listener.local_addr()?;
        let (tx, spans) = mpsc::channel(QUEUE);
        let task = tokio::spawn(async move {
            while let Ok((stream, _)) = listener.accept().await {
                let tx = tx.clone();
                tokio::spawn(async move {
                    let service = hyper::service::service_fn(move |req| answer(req, tx.clone()));
                    let io = hyper_util::rt::TokioIo::new(stream);
                    // A connection that breaks only ends itself; the exporter reconnects.
                    let _ = hyper::server::conn::http1::Builder::new()
                        .serve_connection(io, service)
                        .await;
                });
            }
        });
        Ok(Collector { addr, spans, task })
    }

    /// `http://127.0.0.1:PORT`, the base address exporters are given.
    pub fn url(&self) -> String {
        format!("http://{}", self.addr)
    }

    /// Spans until `done` says the set is complete (it sees every span so far), or fails at `within` naming what
    /// had come.
    pub async fn until(
        &mut self,
        within: Duration,
        what: &str,
        done: impl Fn(&[Received]) -> bool,
    ) -> anyhow::Result<Vec<Received>> {
        eprintln!(
            "waiting up to {} s for {what} at the test collector",
            within.as_secs()
        );
        let deadline = tokio::time::Instant::now() + within;
        let mut got = Vec::new();
        while !done(&got) {
            match tokio::time::timeout_at(deadline, self.spans.recv()).await {
                Ok(Some(span)) => got.push(span),
                Ok(None) => anyhow::bail!("the collector stopped"),
                Err(_) => {
                    let mut names = std::collections::BTreeMap::new();
                    for r in &got {
                        *names
                            .entry(format!("{}:{}", r.service, r.span.name))
                            .or_insert(0usize) += 1;
                    }
                    anyhow::bail!(
                        "no {what} within {} s; spans by name: {names:?}",
                        within.as_secs()
                    );
                }
            }
        }
        Ok(got)
    }

    /// Every span that arrives within `window` (for asserting that nothing comes).
    pub async fn drain(&mut self, window: Duration) -> Vec<Received> {
        let deadline = tokio::time::Instant::now() + window;
        let mut got = Vec::new();
        while let Ok(Some(span)) = tokio::time::timeout_at(deadline, self.spans.recv()).await {
            got.push(span);
        }
        got
    }
}

async fn answer(
    req: Request<Incoming>,
    tx: mpsc::Sender<Received>,
) -> Result<Response<Full<Bytes>>, Infallible> {
    let reply = |status: StatusCode, body: Bytes| {
        let mut r = Response::new(Full::new(body));
        *r.status_mut() = status;
        r.headers_mut().insert(
            "content-type",
            hyper::header::HeaderValue::from_static("application/x-protobuf"),
        );
        r
    };
    if req.uri().path() != "/v1/traces" {
        return Ok(reply(StatusCode::NOT_FOUND, Bytes::new()));
    }
    let body = match req.into_body().collect().await {
        Ok(body) => body.to_bytes(),
        Err(_) => return Ok(reply(StatusCode::BAD_REQUEST, Bytes::new())),
    };
    let Ok(export) = ExportTraceServiceRequest::decode(body) else {
        return Ok(reply(
            StatusCode::BAD_REQUEST,
            Bytes::from_static(b"not an OTLP trace export"),
        ));
    };
    for resource_spans in export.resource_spans {
        let service = resource_spans
            .resource
            .as_ref()
            .and_then(|r| r.attributes.iter().find(|kv| kv.key == "service.name"))
            .and_then(|kv| match kv.value.as_ref()?.value.as_ref()? {
                Value::StringValue(s) => Some(s.clone()),
                _ => None,
            })
            .unwrap_or_default();
        for scope in resource_spans.scope_spans {
            for span in scope.spans {
                let received = Received {
                    service: service.clone(),
                    span,
                };
                if tx.try_send(received).is_err() {
                    return Ok(reply(StatusCode::SERVICE_UNAVAILABLE, Bytes::new()));
                }
            }
        }
    }
    // An empty ExportTraceServiceResponse: every span accepted.
    Ok(reply(StatusCode::OK, Bytes::new()))
}
