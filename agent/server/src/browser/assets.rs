//! The page's files (`web/`) and the avatar's model (`assets/`), embedded in the binary with rust-embed so the
//! single binary serves its own UI.
//!
//! Release builds carry the files inside the executable; debug builds read them from `web/` and `assets/` at run
//! time, which lets a developer edit the page or regenerate the model without rebuilding. `web/vendor/` holds
//! the three.js modules that `scripts/web-deps.sh` copies from npm (only the files the page imports); without
//! them the page's 3D avatar falls back to the 2D face.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use rust_embed::RustEmbed;

#[derive(RustEmbed)]
#[folder = "../../web/"]
struct Web;

/// Served under `/assets/`: generated files the page loads (the 3D avatar's GLB), kept out of `web/` because they
/// are build outputs of `scripts/avatar-gen`, not page source.
#[derive(RustEmbed)]
#[folder = "../../assets/"]
struct Assets;

/// The embedded file for a request path: `assets/...` from the model folder, anything else from the page.
fn lookup(path: &str) -> Option<rust_embed::EmbeddedFile> {
    match path.strip_prefix("assets/") {
        Some(rest) => Assets::get(rest),
        None => Web::get(path),
    }
}

/// The response for asset `path` (no leading slash; empty means the page itself).
pub fn serve(path: &str) -> Response {
    let path = if path.is_empty() { "index.html" } else { path };
    let Some(file) = lookup(path) else {
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
    lookup(path).is_some_and(|f| if_none_match.contains(&hex(&f.metadata.sha256_hash()[..12])))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}
