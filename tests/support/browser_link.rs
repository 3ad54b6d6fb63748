//! The HTTP side of the browser link as a page uses it, for tests and the benchmark that play the page's part.

use anyhow::Context;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// `POST /api/session` on `http` (host:port) with an `Origin` header; returns the status and body.
pub async fn post_session(http: &str, origin: &str) -> anyhow::Result<(u16, String)> {
    let mut s = tokio::net::TcpStream::connect(http).await?;
    let req = format!(
        "POST /api/session HTTP/1.1\r\nHost: {http}\r\nOrigin: {origin}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
    );
    s.write_all(req.as_bytes()).await?;
    let mut buf = Vec::new();
    s.read_to_end(&mut buf).await?;
    let text = String::from_utf8_lossy(&buf).to_string();
    let status = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .context("no HTTP status")?;
    let body = text
        .split_once("\r\n\r\n")
        .map(|(_, b)| b.to_string())
        .unwrap_or_default();
    Ok((status, body))
}

/// A session token for the page at `http`, asked for with the server's own origin.
pub async fn session_token(http: &str) -> anyhow::Result<String> {
    let (status, body) = post_session(http, &format!("http://{http}")).await?;
    anyhow::ensure!(status == 200, "session refused with {status}: {body}");
    let v: serde_json::Value = serde_json::from_str(body.trim())?;
    Ok(v["session"]
        .as_str()
        .context("no session in the answer")?
        .to_string())
}
