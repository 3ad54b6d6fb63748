//! HTTP side of the browser link: the page's files, the session endpoint and the WebSocket upgrade.

use std::sync::Arc;
use std::time::Instant;

use axum::Router;
use axum::extract::ws::WebSocketUpgrade;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde::Deserialize;

use super::{Shared, assets, lock, socket, wire};

pub fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(index))
        .route("/api/session", post(new_session))
        .route("/link", get(link))
        .route("/{*path}", get(asset))
        .with_state(shared)
}

async fn index(headers: HeaderMap) -> Response {
    asset_response("", &headers)
}

async fn asset(Path(path): Path<String>, headers: HeaderMap) -> Response {
    asset_response(&path, &headers)
}

fn asset_response(path: &str, headers: &HeaderMap) -> Response {
    let inm = headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok());
    if inm.is_some_and(|v| assets::not_modified(path, v)) {
        return StatusCode::NOT_MODIFIED.into_response();
    }
    assets::serve(path)
}

fn header(headers: &HeaderMap, name: header::HeaderName) -> Option<&str> {
    headers.get(name).and_then(|v| v.to_str().ok())
}

async fn new_session(State(shared): State<Arc<Shared>>, headers: HeaderMap) -> Response {
    let host = header(&headers, header::HOST);
    let origin = header(&headers, header::ORIGIN);
    // Browsers send Origin on a fetch POST; a tool without one (curl) is not a cross-site page.
    if !shared.origin.allows(host, origin, false) {
        tracing::warn!(?host, ?origin, "session refused: not our own origin");
        return (StatusCode::FORBIDDEN, "forbidden origin").into_response();
    }
    let token = lock(&shared.sessions).issue(Instant::now());
    let body = serde_json::json!({
        "session": token,
        "link": "/link",
        "expires_in_s": shared.session_ttl_s,
    });
    ([(header::CACHE_CONTROL, "no-store")], axum::Json(body)).into_response()
}

#[derive(Debug, Deserialize)]
struct LinkQuery {
    session: Option<String>,
}

async fn link(
    State(shared): State<Arc<Shared>>,
    Query(q): Query<LinkQuery>,
    headers: HeaderMap,
    upgrade: WebSocketUpgrade,
) -> Response {
    let host = header(&headers, header::HOST);
    let origin = header(&headers, header::ORIGIN);
    if !shared.origin.allows(host, origin, true) {
        tracing::warn!(?host, ?origin, "link refused: not our own origin");
        return (StatusCode::FORBIDDEN, "forbidden origin").into_response();
    }
    if shared.client.get().is_none() {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            "the browser link is not running",
        )
            .into_response();
    }
    let Some(token) = q.session else {
        return (StatusCode::FORBIDDEN, "missing session").into_response();
    };
    if let Err(e) = lock(&shared.sessions).bind(&token, Instant::now()) {
        tracing::warn!(error = %e, "link refused");
        return (StatusCode::FORBIDDEN, e.to_string()).into_response();
    }
    let failed = (shared.clone(), token.clone());
    upgrade
        .max_message_size(wire::HEADER_BYTES + wire::MAX_VIDEO_BYTES)
        .on_failed_upgrade(move |e| {
            tracing::warn!(error = %e, "WebSocket upgrade failed");
            lock(&failed.0.sessions).unbind(&failed.1, Instant::now());
        })
        .on_upgrade(move |ws| async move { socket::run(shared, ws, &token).await })
}
