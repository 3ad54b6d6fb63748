//! The HTTP side of the browser link as a page uses it, for tests and the benchmark that play the page's part,
//! and the server set-up they share.

use anyhow::Context;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// `POST /api/session` on `http` (host:port) with an `Origin` header and `page_token` as the bearer credential;
/// returns the status and body.
pub async fn post_session(
    http: &str,
    origin: &str,
    page_token: &str,
) -> anyhow::Result<(u16, String)> {
    let mut s = tokio::net::TcpStream::connect(http).await?;
    let req = format!(
        "POST /api/session HTTP/1.1\r\nHost: {http}\r\nOrigin: {origin}\r\nAuthorization: Bearer {page_token}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
    );
    s.write_all(req.as_bytes()).await?;
    let mut buf = Vec::new();
    tokio::time::timeout(crate::wait::PATIENCE, s.read_to_end(&mut buf))
        .await
        .context("POST /api/session: no complete answer in time")??;
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
pub async fn session_token(http: &str, page_token: &str) -> anyhow::Result<String> {
    let (status, body) = post_session(http, &format!("http://{http}"), page_token).await?;
    anyhow::ensure!(status == 200, "session refused with {status}: {body}");
    let v: serde_json::Value = serde_json::from_str(body.trim())?;
    Ok(v["session"]
        .as_str()
        .context("no session in the answer")?
        .to_string())
}

/// Server configuration for the browser tests and benchmark: the modules that publish avatar commands, speech and
/// detections themselves (or process the camera) are off (the behaviour controllers are part of tts), so the test owns those channels and measures the link
/// alone. Their own tests cover them.
pub const LINK_ONLY_CONFIG: &str = "\
[modules.tts]
enabled = false
[modules.brain]
enabled = false
[modules.vision]
enabled = false
";

/// Starts a robot-agent with [`LINK_ONLY_CONFIG`] in `data`.
pub async fn start_link_only(data: &crate::agent::DataDir) -> anyhow::Result<crate::agent::Agent> {
    let opts = crate::agent::AgentOptions {
        config: Some(LINK_ONLY_CONFIG.into()),
        ..Default::default()
    };
    crate::agent::Agent::start_with(data, opts).await
}
