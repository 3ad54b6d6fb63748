//! Who may use the HTTP edge. The page credential is the page token (`data/page.token`), which the URL printed at
//! start carries (`/?token=...`, as Jupyter does); the page exchanges it for an HttpOnly, SameSite=Strict session
//! cookie, signed with that token so that it outlives a restart and dies with the token. Tools present a token as
//! `Authorization: Bearer`. Every request but `/healthz` must name a host this server answers to, which stops
//! DNS-rebinding pages; `/flow` is let through to FlowProtocol's own login. The threat model is docs/security.md.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use axum::extract::{ConnectInfo, Query, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::{Html, IntoResponse, Response};
use hmac::{Hmac, KeyInit, Mac};
use sha2::Sha256;

use crate::tokens::Tokens;

/// Both ends of an HTTP connection: the local address tells which IP literal in `Host` is really ours.
#[derive(Debug, Clone, Copy)]
pub struct PeerInfo {
    pub remote: SocketAddr,
    pub local: Option<SocketAddr>,
}

/// What let a request in; the browser link counts its sockets per credential.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Credential {
    /// A page session cookie, named by its nonce.
    Cookie(String),
    /// A token in `Authorization: Bearer` (page, user or admin token).
    Bearer,
    /// `http.open_on_loopback`: no credential asked.
    Open,
}

impl Credential {
    /// A key for per-credential counts.
    pub fn key(&self) -> &str {
        match self {
            Credential::Cookie(nonce) => nonce,
            Credential::Bearer => "bearer",
            Credential::Open => "open",
        }
    }
}

/// The access policy of one server.
#[derive(Debug)]
pub struct Access {
    tokens: Tokens,
    cookie_name: String,
    cookie_ttl: Duration,
    allowed_hosts: Vec<String>,
    open: bool,
    /// Served over HTTPS: the cookie is marked `Secure`, so the browser never sends it over plain HTTP.
    secure: bool,
}

type HmacSha256 = Hmac<Sha256>;

/// A cookie is `ISSUED.NONCE.MAC`: issue time in Unix seconds, 64 random bits in hex, and the HMAC-SHA256 of
/// both under the page token, in hex.
const COOKIE_DOMAIN: &str = "robot-agent page session v1";

impl Access {
    /// `port` names the cookie: cookies are per host, not per port, and two servers on one machine must not read
    /// each other's.
    pub fn new(
        tokens: Tokens,
        port: u16,
        cookie_ttl: Duration,
        allowed_hosts: Vec<String>,
        open: bool,
    ) -> Self {
        Access {
            tokens,
            cookie_name: format!("robot_agent_{port}"),
            cookie_ttl,
            allowed_hosts,
            open,
            secure: false,
        }
    }

    /// The page is served over HTTPS: cookies are marked `Secure`.
    pub fn over_tls(mut self, tls: bool) -> Self {
        self.secure = tls;
        self
    }

    /// Whether no credential is asked (`http.open_on_loopback`).
    pub fn is_open(&self) -> bool {
        self.open
    }

    fn mac(&self, issued: u64, nonce: &str) -> HmacSha256 {
        // HMAC takes keys of any length; this cannot fail.
        let mut mac = HmacSha256::new_from_slice(self.tokens.page().as_bytes())
            .unwrap_or_else(|_| unreachable!("HMAC accepts any key length"));
        mac.update(format!("{COOKIE_DOMAIN}|{issued}|{nonce}").as_bytes());
        mac
    }

    /// A fresh session cookie, as a `Set-Cookie` value.
    pub fn new_cookie(&self, now: SystemTime) -> String {
        let issued = now.duration_since(UNIX_EPOCH).unwrap_or_default().as_secs();
        let nonce = format!("{:016x}", rand::random::<u64>());
        let tag = hex(&self.mac(issued, &nonce).finalize().into_bytes());
        format!(
            "{}={issued}.{nonce}.{tag}; Path=/; HttpOnly; SameSite=Strict; Max-Age={}{}",
            self.cookie_name,
            self.cookie_ttl.as_secs(),
            if self.secure { "; Secure" } else { "" }
        )
    }

    /// The nonce of a valid, unexpired session cookie among `headers`.
    fn cookie(&self, headers: &HeaderMap, now: SystemTime) -> Option<String> {
        let now = now.duration_since(UNIX_EPOCH).unwrap_or_default().as_secs();
        headers
            .get_all(header::COOKIE)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(';'))
            .filter_map(|pair| pair.trim().split_once('='))
            .filter(|(name, _)| *name == self.cookie_name)
            .find_map(|(_, value)| {
                let mut parts = value.splitn(3, '.');
                let issued: u64 = parts.next()?.parse().ok()?;
                let nonce = parts.next()?;
                let tag = unhex(parts.next()?)?;
                let fresh = issued <= now + 60 && now - issued.min(now) < self.cookie_ttl.as_secs();
                (fresh && self.mac(issued, nonce).verify_slice(&tag).is_ok())
                    .then(|| nonce.to_string())
            })
    }

    /// Whether an `Authorization: Bearer` header carries the page, user or admin token.
    fn bearer(&self, headers: &HeaderMap) -> bool {
        header_str(headers, header::AUTHORIZATION)
            .and_then(|v| v.strip_prefix("Bearer "))
            .is_some_and(|t| self.tokens.is_page(t.trim()) || self.tokens.check(t.trim()).is_some())
    }

    /// What lets this request in, if anything.
    pub fn credential(&self, headers: &HeaderMap, now: SystemTime) -> Option<Credential> {
        if let Some(nonce) = self.cookie(headers, now) {
            Some(Credential::Cookie(nonce))
        } else if self.bearer(headers) {
            Some(Credential::Bearer)
        } else {
            self.open.then_some(Credential::Open)
        }
    }

    /// Whether `host` (a `Host` header value) names this server: `localhost`, a loopback address, the address the
    /// client connected to, or a configured name. A DNS-rebinding page carries its own name and fails here.
    pub fn host_is_ours(&self, host: &str, local: Option<SocketAddr>) -> bool {
        let name = host_name(host);
        if name.eq_ignore_ascii_case("localhost") {
            return true;
        }
        if let Ok(ip) = name.parse::<IpAddr>() {
            return ip.is_loopback() || local.is_some_and(|l| l.ip() == ip);
        }
        self.allowed_hosts
            .iter()
            .any(|h| h.eq_ignore_ascii_case(name))
    }
}

/// Whether a request's `Origin` is the page's own (the `Host` it was sent to). `require_origin`: browsers send
/// Origin on every WebSocket and fetch POST, so its absence means a tool, which is acceptable only where the
/// caller says so.
pub fn same_origin(host: Option<&str>, origin: Option<&str>, require_origin: bool) -> bool {
    let Some(host) = host else { return false };
    match origin {
        None => !require_origin,
        Some(origin) => origin
            .strip_prefix("http://")
            .or_else(|| origin.strip_prefix("https://"))
            .is_some_and(|authority| authority.eq_ignore_ascii_case(host)),
    }
}

/// The name part of a `Host` header value (`[::1]:8080` -> `::1`, `localhost:8080` -> `localhost`).
fn host_name(host: &str) -> &str {
    if let Some(rest) = host.strip_prefix('[') {
        return rest.split(']').next().unwrap_or(rest);
    }
    match host.rsplit_once(':') {
        Some((name, port)) if port.chars().all(|c| c.is_ascii_digit()) => name,
        _ => host,
    }
}

pub fn header_str(headers: &HeaderMap, name: header::HeaderName) -> Option<&str> {
    headers.get(name).and_then(|v| v.to_str().ok())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) {
        return None;
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(text.get(i..i + 2)?, 16).ok())
        .collect()
}

/// The middleware in front of every route: host check, the token-to-cookie exchange at `/?token=`, and the
/// credential check; a request let in carries its [`Credential`] as an extension.
pub async fn gate(State(access): State<Arc<Access>>, mut req: Request, next: Next) -> Response {
    let path = req.uri().path().to_string();
    if path == "/healthz" {
        return next.run(req).await;
    }
    let local = req
        .extensions()
        .get::<ConnectInfo<PeerInfo>>()
        .and_then(|c| c.0.local);
    let host = header_str(req.headers(), header::HOST).unwrap_or_default();
    if !access.host_is_ours(host, local) {
        tracing::warn!(%host, %path, "request refused: Host is not a name of this server");
        return (
            StatusCode::FORBIDDEN,
            "unknown host: add it to [http] allowed_hosts to reach this server under that name\n",
        )
            .into_response();
    }
    // FlowProtocol authenticates its own connections (and `/flow` checks Origin itself).
    if path == "/flow" {
        return next.run(req).await;
    }
    let now = SystemTime::now();
    if path == "/" {
        let query = Query::<HashMap<String, String>>::try_from_uri(req.uri())
            .map(|q| q.0)
            .unwrap_or_default();
        if let Some(presented) = query.get("token") {
            let res = exchange(
                &access,
                req.uri().query().unwrap_or_default(),
                presented,
                now,
            );
            if res.status() == StatusCode::SEE_OTHER
                && let Some(conn) = req.extensions().get::<super::connection::HttpConn>()
            {
                conn.known();
            }
            return res;
        }
    }
    match access.credential(req.headers(), now) {
        Some(credential) => {
            if let Some(conn) = req.extensions().get::<super::connection::HttpConn>() {
                conn.known();
            }
            req.extensions_mut().insert(credential);
            next.run(req).await
        }
        None => refuse(&path, None),
    }
}

/// `/?token=...`: a right page token gets a cookie and a redirect to the same address without the token (so that
/// it stays out of the history and the address bar); a wrong one gets the sign-in page.
fn exchange(access: &Access, raw_query: &str, presented: &str, now: SystemTime) -> Response {
    // The form on the sign-in page accepts the whole printed URL as well as the bare token.
    let token = presented
        .rsplit_once("token=")
        .map_or(presented, |(_, t)| t)
        .trim();
    if !access.tokens.is_page(token) {
        tracing::warn!("page sign-in refused: wrong token");
        return refuse("/", Some("That token is not this server's page token."));
    }
    let rest: Vec<&str> = raw_query
        .split('&')
        .filter(|p| !p.is_empty() && !p.starts_with("token="))
        .collect();
    let location = if rest.is_empty() {
        "/".to_string()
    } else {
        format!("/?{}", rest.join("&"))
    };
    let mut res = StatusCode::SEE_OTHER.into_response();
    let headers = res.headers_mut();
    if let (Ok(cookie), Ok(location)) = (
        HeaderValue::from_str(&access.new_cookie(now)),
        HeaderValue::from_str(&location),
    ) {
        headers.insert(header::SET_COOKIE, cookie);
        headers.insert(header::LOCATION, location);
    }
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    tracing::info!("page signed in");
    res
}

/// 401 in the shape the route's caller reads: the sign-in page for the page itself, JSON for the API, text else.
fn refuse(path: &str, problem: Option<&str>) -> Response {
    let message = "no valid credential: open the address robot-agent printed at start (it ends in ?token=...)";
    if path == "/" || path.ends_with(".html") {
        let page = SIGN_IN_PAGE.replace("{problem}", problem.unwrap_or(""));
        return (
            StatusCode::UNAUTHORIZED,
            [(header::CACHE_CONTROL, "no-store")],
            Html(page),
        )
            .into_response();
    }
    if path.starts_with("/api/") {
        return (
            StatusCode::UNAUTHORIZED,
            axum::Json(serde_json::json!({ "error": message })),
        )
            .into_response();
    }
    (StatusCode::UNAUTHORIZED, format!("{message}\n")).into_response()
}

/// The page shown without a credential: how to get in, and a form for the token.
const SIGN_IN_PAGE: &str = r#"<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>robot-agent: sign in</title>
<style>
  body { font: 16px/1.5 system-ui, sans-serif; background: #101418; color: #e8ecef; margin: 0; display: grid;
         place-items: center; min-height: 100vh; }
  main { max-width: 36rem; padding: 2rem; background: #1a2026; border-radius: 12px; }
  code { background: #0b0e11; padding: 0 .3em; border-radius: 4px; }
  input { width: 100%; box-sizing: border-box; padding: .5em; margin: .5em 0; font: inherit; }
  button { padding: .5em 1.2em; font: inherit; }
  .problem { color: #ff8a80; }
</style>
</head>
<body>
<main>
<h1>Sign in to robot-agent</h1>
<p class="problem" id="problem">{problem}</p>
<p>This page needs its credential. Open the address <code>robot-agent</code> printed when it started; it ends in
<code>?token=...</code>. The token is also in the server's data directory, in <code>data/page.token</code>.</p>
<form method="get" action="/">
<label for="token">Page token (or the whole address):</label>
<input id="token" name="token" autocomplete="off" autofocus>
<button type="submit">Sign in</button>
</form>
</main>
</body>
</html>
"#;

#[cfg(test)]
mod tests {
    use super::*;

    fn access(open: bool) -> (Access, tempfile::TempDir) {
        let dir = tempfile::tempdir().expect("temp dir");
        let tokens = Tokens::load_or_create(dir.path()).expect("tokens");
        let a = Access::new(
            tokens,
            8080,
            Duration::from_secs(3600),
            vec!["robot.local".into()],
            open,
        );
        (a, dir)
    }

    fn with_cookie(value: &str) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert(
            header::COOKIE,
            HeaderValue::from_str(value).expect("header"),
        );
        h
    }

    #[test]
    fn a_minted_cookie_is_accepted_until_it_expires() {
        let (a, _dir) = access(false);
        let t0 = SystemTime::now();
        let set = a.new_cookie(t0);
        let pair = set.split(';').next().expect("pair");
        assert!(
            set.contains("HttpOnly") && set.contains("SameSite=Strict"),
            "{set}"
        );
        let h = with_cookie(&format!("other=1; {pair}"));
        assert!(matches!(a.credential(&h, t0), Some(Credential::Cookie(_))));
        assert_eq!(
            a.credential(&h, t0 + Duration::from_secs(3601)),
            None,
            "expired"
        );
    }

    #[test]
    fn forged_or_foreign_cookies_are_refused() {
        let (a, _dir) = access(false);
        let (b, _dir2) = access(false);
        let t0 = SystemTime::now();
        let theirs = b.new_cookie(t0);
        let pair = theirs.split(';').next().expect("pair");
        assert_eq!(
            a.credential(&with_cookie(pair), t0),
            None,
            "signed with another page token"
        );
        let mine = a.new_cookie(t0);
        let pair = mine.split(';').next().expect("pair");
        let (head, tag) = pair.rsplit_once('.').expect("tag");
        let flipped = if tag.starts_with('0') { "1" } else { "0" };
        let forged = format!("{head}.{flipped}{}", &tag[1..]);
        assert_eq!(a.credential(&with_cookie(&forged), t0), None);
        assert_eq!(
            a.credential(&with_cookie("robot_agent_8080=garbage"), t0),
            None
        );
    }

    #[test]
    fn bearer_tokens_and_the_open_setting() {
        let (a, dir) = access(false);
        let page = std::fs::read_to_string(dir.path().join("page.token")).expect("page token");
        let mut h = HeaderMap::new();
        h.insert(
            header::AUTHORIZATION,
            HeaderValue::from_str(&format!("Bearer {}", page.trim())).expect("header"),
        );
        assert_eq!(
            a.credential(&h, SystemTime::now()),
            Some(Credential::Bearer)
        );
        h.insert(
            header::AUTHORIZATION,
            HeaderValue::from_static("Bearer wrong"),
        );
        assert_eq!(a.credential(&h, SystemTime::now()), None);
        let (open, _d) = access(true);
        assert_eq!(
            open.credential(&HeaderMap::new(), SystemTime::now()),
            Some(Credential::Open)
        );
    }

    #[test]
    fn hosts_are_loopback_the_connected_address_or_configured() {
        let (a, _dir) = access(false);
        let local: SocketAddr = "192.168.1.20:8080".parse().expect("addr");
        assert!(a.host_is_ours("127.0.0.1:8080", None));
        assert!(a.host_is_ours("localhost:8080", None));
        assert!(a.host_is_ours("[::1]:8080", None));
        assert!(a.host_is_ours("192.168.1.20:8080", Some(local)));
        assert!(a.host_is_ours("ROBOT.local:8080", None));
        assert!(
            !a.host_is_ours("10.6.6.6:8080", Some(local)),
            "an IP that is not ours"
        );
        assert!(
            !a.host_is_ours("evil.example:8080", Some(local)),
            "DNS rebinding"
        );
        assert!(!a.host_is_ours("", Some(local)));
    }

    #[test]
    fn origins_must_match_the_host() {
        assert!(same_origin(
            Some("127.0.0.1:8080"),
            Some("http://127.0.0.1:8080"),
            true
        ));
        assert!(same_origin(
            Some("[::1]:8080"),
            Some("https://[::1]:8080"),
            true
        ));
        assert!(!same_origin(
            Some("127.0.0.1:8080"),
            Some("http://evil.example"),
            true
        ));
        assert!(!same_origin(
            Some("127.0.0.1:8080"),
            Some("http://127.0.0.1:9999"),
            true
        ));
        assert!(!same_origin(Some("127.0.0.1:8080"), Some("null"), true));
        assert!(!same_origin(Some("127.0.0.1:8080"), None, true));
        assert!(same_origin(Some("127.0.0.1:8080"), None, false));
        assert!(!same_origin(None, Some("http://127.0.0.1:8080"), false));
    }
}
