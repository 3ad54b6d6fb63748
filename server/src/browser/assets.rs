//! The page's files (`web/`), embedded in the binary with rust-embed so the single binary serves its own UI.
//!
//! Release builds carry the files inside the executable; debug builds read them from `web/` at run time, which
//! lets a developer edit the page without rebuilding.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use rust_embed::RustEmbed;

#[derive(RustEmbed)]
#[folder = "../web/"]
struct Web;

/// The response for asset `path` (no leading slash; empty means the page itself).
pub fn serve(path: &str) -> Response {
    let path = if path.is_empty() { "index.html" } else { path };
    let Some(file) = Web::get(path) else {
        return (StatusCode::NOT_FOUND, "not found").into_response();
    };
    let etag = format!("\"{}\"", hex(&file.metadata.sha256_hash()[..12]));
    let mut res = Response::new(axum::body::Body::from(file.data.into_owned()));
    let headers = res.headers_mut();
    if let Ok(v) = HeaderValue::from_str(file.metadata.mimetype()) {
        headers.insert(header::CONTENT_TYPE, v);
    }
    if let Ok(v) = HeaderValue::from_str(&etag) {
        headers.insert(header::ETAG, v);
    }
    // The page and its modules change with the binary: always revalidate (cheap, thanks to the ETag).
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    headers.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    res
}

/// Whether an `If-None-Match` value matches the current version of `path`.
pub fn not_modified(path: &str, if_none_match: &str) -> bool {
    let path = if path.is_empty() { "index.html" } else { path };
    Web::get(path).is_some_and(|f| if_none_match.contains(&hex(&f.metadata.sha256_hash()[..12])))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}
