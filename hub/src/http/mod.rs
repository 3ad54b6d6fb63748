//! The HTTP edge: health, JSON status APIs and the WebSocket flow link. Who may call them is decided in front of
//! every route by [`access::gate`].

pub mod access;

use std::sync::Arc;

use axum::Router;
use axum::extract::{ConnectInfo, State, WebSocketUpgrade};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde_json::{Value, json};

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
        .route("/healthz", get(|| async { "ok" }))
        .route("/api/channels", get(channels))
        .route("/api/status", get(status))
        .route("/flow", get(flow_link))
        .with_state(shared)
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
    ws.max_message_size(flow::transport::WS_MESSAGE_MAX)
        .max_frame_size(flow::transport::WS_MESSAGE_MAX)
        .on_upgrade(move |socket| async move {
            serve_connection(
                WsServerTransport::new(socket, format!("ws:{peer}")),
                shared,
                false,
            )
            .await;
        })
}
