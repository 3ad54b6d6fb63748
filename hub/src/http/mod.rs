//! The HTTP edge: health, JSON status APIs, Prometheus metrics and the WebSocket flow link. Who may call them is decided in front of
//! every route by [`access::gate`].

pub mod access;
pub mod connection;
pub mod serve;
pub mod tls;

use std::sync::Arc;

use axum::Router;
use axum::extract::{ConnectInfo, State, WebSocketUpgrade};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde_json::{Value, json};

use crate::admission::Origin;
use crate::net::serve_connection;
use crate::net::ws::WsServerTransport;
use crate::shared::Shared;
use access::{PeerInfo, header_str, same_origin};

/// Errors at HTTP handlers, turned into a status and a JSON body.
#[derive(Debug)]
pub struct AppError(pub StatusCode, pub String);

impl IntoResponse for AppError {
    fn into_response(self) -> Response {
        (self.0, axum::Json(json!({ "error": self.1 }))).into_response()
    }
}

/// The router, built from shared state so tests can serve it on any port.
pub fn app(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/healthz", get(healthz))
        .route("/api/channels", get(channels))
        .route("/api/status", get(status))
        .route("/metrics", get(metrics))
        .route("/api/graph", get(graph))
        .route("/api/graph/stream", get(graph_stream))
        .route("/flow", get(flow_link))
        .with_state(shared)
}

/// The header of `/healthz` that tells the hub's clock, in microseconds since the Unix epoch: satellites stamp spans
/// and transcripts on their own clocks, and `robot-agent doctor` on a satellite's machine compares them with this
/// one (an HTTP `Date` header has only whole seconds).
pub const HUB_TIME_HEADER: &str = "x-hub-time-us";

/// `GET /healthz`: `ok` to anyone, with the hub's clock in [`HUB_TIME_HEADER`].
async fn healthz() -> impl IntoResponse {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros());
    ([(HUB_TIME_HEADER, now.to_string())], "ok")
}

/// `GET /metrics`: the Prometheus text exposition (a scraper sends `Authorization: Bearer` with a token, as every
/// tool does).
async fn metrics(State(shared): State<Arc<Shared>>) -> Result<Response, AppError> {
    let text = shared.metrics.render().map_err(|e| {
        AppError(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("encoding the metrics: {e}"),
        )
    })?;
    Ok((
        [(
            header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        text,
    )
        .into_response())
}

/// `GET /api/graph`: every connection and every channel between them, with rates.
async fn graph(State(shared): State<Arc<Shared>>) -> axum::Json<crate::hub::Graph> {
    axum::Json(shared.hub.graph())
}

/// How often `/api/graph/stream` sends the graph: the hub's rates change once a second too.
const GRAPH_PERIOD: std::time::Duration = std::time::Duration::from_secs(1);

/// `GET /api/graph/stream`: the graph as server-sent events, one `graph` event a second, until the page leaves or
/// the server shuts down. Only the connected pages cost anything; an idle server sends nothing.
async fn graph_stream(
    State(shared): State<Arc<Shared>>,
) -> axum::response::sse::Sse<
    impl futures_util::Stream<Item = Result<axum::response::sse::Event, std::convert::Infallible>>,
> {
    use axum::response::sse::{Event, KeepAlive, Sse};
    let mut ticks = tokio::time::interval(GRAPH_PERIOD);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let shutdown = shared.shutdown.subscribe();
    let stream = futures_util::stream::unfold(
        (shared, ticks, shutdown),
        |(shared, mut ticks, mut shutdown)| async move {
            tokio::select! {
                _ = ticks.tick() => {}
                _ = shutdown.wait_for(|down| *down) => return None,
            }
            let graph = serde_json::to_string(&shared.hub.graph()).unwrap_or_default();
            let event = Event::default().event("graph").data(graph);
            Some((Ok(event), (shared, ticks, shutdown)))
        },
    );
    Sse::new(stream).keep_alive(KeepAlive::default())
}

/// `GET /api/channels`: every channel with its counters.
async fn channels(State(shared): State<Arc<Shared>>) -> axum::Json<Vec<Value>> {
    let list = shared
        .hub
        .list_channels()
        .into_iter()
        .map(|c| {
            let header: Value = serde_json::from_str(&c.header).unwrap_or(Value::Null);
            json!({
                "id": c.id,
                "name": c.name,
                "hash": format!("{:016x}", c.hash),
                "kind": c.kind.as_str(),
                "owner": c.owner,
                "subscribers": c.stats.subscribers,
                "header": header,
                "msgs": c.stats.msgs,
                "bytes": c.stats.bytes,
                "msgs_per_s": c.stats.msgs_per_s,
                "bytes_per_s": c.stats.bytes_per_s,
                "dropped": c.stats.dropped,
            })
        })
        .collect();
    axum::Json(list)
}

/// `GET /api/status`: connections, tick jitter and module reports.
async fn status(State(shared): State<Arc<Shared>>) -> Result<axum::Json<Value>, AppError> {
    let ticks = shared.pulses.stats();
    let jitter = |s: flow::tick::JitterStats| json!({ "ticks": s.ticks, "mean_us": s.mean_us, "p50_us": s.p50_us, "p99_us": s.p99_us, "max_us": s.max_us });
    Ok(axum::Json(json!({
        "connections": shared.hub.connection_count(),
        "ticks": {
            "fast": jitter(ticks.fast),
            "slow": jitter(ticks.slow),
            "one_sec": jitter(ticks.one_sec),
        },
        "modules": shared.module_reports(),
    })))
}

/// `GET /flow`: FlowProtocol over WebSocket binary messages. Tools send no `Origin`; a browser always does, and then
/// it must be the server's own, or any web page the operator visits could open hub connections.
async fn flow_link(
    State(shared): State<Arc<Shared>>,
    ConnectInfo(peer): ConnectInfo<PeerInfo>,
    conn: Option<axum::Extension<connection::HttpConn>>,
    headers: HeaderMap,
    ws: WebSocketUpgrade,
) -> Response {
    let peer = peer.remote;
    let host = header_str(&headers, header::HOST);
    let origin = header_str(&headers, header::ORIGIN);
    if !same_origin(host, origin, false) {
        tracing::warn!(%peer, ?origin, "flow link refused: a browser page of another origin");
        return (StatusCode::FORBIDDEN, "forbidden origin").into_response();
    }
    // The byte stream arrives in messages of at most WS_MESSAGE_MAX; frames are reassembled and checked by size
    // behind it, so one message never holds more than that before the frame check.
    // The connection's place among the strangers goes with it until FlowProtocol's login (a router served
    // without the edge's own loop, as in tests, takes a place here).
    let stranger = conn
        .and_then(|c| c.take_stranger())
        .unwrap_or_else(|| shared.admission.admit(Origin::ip(peer.ip())));
    ws.max_message_size(flow::transport::WS_MESSAGE_MAX)
        .max_frame_size(flow::transport::WS_MESSAGE_MAX)
        .on_failed_upgrade(move |e| {
            tracing::warn!(%peer, "flow link: the WebSocket upgrade failed: {e}");
        })
        .on_upgrade(move |socket| async move {
            serve_connection(
                WsServerTransport::new(socket, format!("ws:{peer}")),
                shared,
                false,
                stranger,
            )
            .await;
        })
}
