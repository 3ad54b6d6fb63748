//! HTTP side of the browser link: the page's files, the session endpoint and the WebSocket upgrade. The server's
//! access gate (`flow_hub::http::access`) has let every request here in with a credential; this side checks Origin
//! and caps the sockets per credential.

use std::sync::Arc;
use std::time::Instant;

use axum::Router;
use axum::extract::ws::WebSocketUpgrade;
use axum::extract::{Extension, Path, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde::Deserialize;

use super::links::{LinkBoard, LinkSlot};
use super::state::{Shared, lock};
use super::{assets, socket, wire};
use flow_hub::http::access::{Credential, header_str as header, same_origin};

pub fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(index))
        .route("/graph", get(graph_page))
        .route("/api/session", post(new_session))
        .route("/link", get(link))
        .route("/{*path}", get(asset))
        .with_state(shared)
}

async fn index(headers: HeaderMap) -> Response {
    asset_response("", &headers)
}

/// The live application graph (`web/graph.html`), linked from the page's top bar.
async fn graph_page(headers: HeaderMap) -> Response {
    asset_response("graph.html", &headers)
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

/// The key the link caps count under; requests without a credential never get past the gate.
fn credential_key(credential: Option<&Extension<Credential>>) -> &str {
    credential.map_or("none", |c| c.0.key())
}

async fn new_session(
    State(shared): State<Arc<Shared>>,
    credential: Option<Extension<Credential>>,
    headers: HeaderMap,
) -> Response {
    let host = header(&headers, header::HOST);
    let origin = header(&headers, header::ORIGIN);
    // Browsers send Origin on a fetch POST; a tool without one (curl) is not a cross-site page.
    if !same_origin(host, origin, false) {
        tracing::warn!(?host, ?origin, "session refused: not our own origin");
        return (StatusCode::FORBIDDEN, "forbidden origin").into_response();
    }
    // Refused here too, where the page can read the reason (a refused WebSocket upgrade shows it nothing).
    if let Err(e) = lock::<LinkBoard>(&shared.links).check(credential_key(credential.as_ref())) {
        tracing::warn!(error = %e, "session refused");
        return too_many(&e.to_string());
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

fn too_many(reason: &str) -> Response {
    (
        StatusCode::TOO_MANY_REQUESTS,
        axum::Json(serde_json::json!({ "error": reason })),
    )
        .into_response()
}

async fn link(
    State(shared): State<Arc<Shared>>,
    credential: Option<Extension<Credential>>,
    Query(q): Query<LinkQuery>,
    headers: HeaderMap,
    upgrade: WebSocketUpgrade,
) -> Response {
    let host = header(&headers, header::HOST);
    let origin = header(&headers, header::ORIGIN);
    if !same_origin(host, origin, true) {
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
    let slot = match LinkSlot::take(&shared.links, credential_key(credential.as_ref())) {
        Ok(slot) => slot,
        Err(e) => {
            tracing::warn!(error = %e, "link refused");
            return too_many(&e.to_string());
        }
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
        .on_upgrade(move |ws| async move {
            // The slot is held for as long as the socket lives.
            socket::run(shared, ws, &token).await;
            drop(slot);
        })
}
