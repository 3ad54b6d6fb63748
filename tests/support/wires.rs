//! What the tests and benches of the serial and UDP wires share: linked pseudo-terminals, payloads that prove
//! themselves intact, and a hub with its UDP edge on a free port.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use anyhow::{Context, ensure};
use flow_lite::crc::crc32;

use crate::{Agent, DataDir, PATIENCE};

/// Two linked pseudo-terminals, `a` and `b`, made by Debian's `socat`; killed when dropped.
#[derive(Debug)]
pub struct PtyPair {
    child: Child,
    pub a: PathBuf,
    pub b: PathBuf,
}

impl PtyPair {
    pub async fn open(a: &Path, b: &Path) -> anyhow::Result<PtyPair> {
        let child = Command::new("socat")
            .arg(format!("pty,raw,echo=0,link={}", a.display()))
            .arg(format!("pty,raw,echo=0,link={}", b.display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .context("starting socat (make deps installs it)")?;
        let deadline = tokio::time::Instant::now() + PATIENCE;
        while !(a.exists() && b.exists()) {
            ensure!(
                tokio::time::Instant::now() < deadline,
                "socat made no pseudo-terminals"
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        Ok(PtyPair {
            child,
            a: a.to_path_buf(),
            b: b.to_path_buf(),
        })
    }

    /// Kills socat: both terminals go away.
    pub fn close(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_file(&self.a);
        let _ = std::fs::remove_file(&self.b);
    }
}

impl Drop for PtyPair {
    fn drop(&mut self) {
        self.close();
    }
}

/// A payload that proves itself: `[seq u32][crc32 of the rest u32][bytes]`.
pub fn payload(seq: u32, len: usize) -> Vec<u8> {
    let body: Vec<u8> = (0..len)
        .map(|i| (i as u32).wrapping_mul(31).wrapping_add(seq) as u8)
        .collect();
    let mut p = seq.to_le_bytes().to_vec();
    p.extend(crc32(&body).to_le_bytes());
    p.extend(body);
    p
}

/// The sequence number of an intact [`payload`]; an error for a damaged one.
pub fn check(p: &[u8]) -> anyhow::Result<u32> {
    ensure!(p.len() >= 8, "payload of {} bytes", p.len());
    let seq = u32::from_le_bytes(p[0..4].try_into()?);
    let crc = u32::from_le_bytes(p[4..8].try_into()?);
    ensure!(crc32(&p[8..]) == crc, "payload {seq} is damaged");
    Ok(seq)
}

/// A bare hub with its UDP edge on a free port and `more` configuration, and that port (read from its log).
pub async fn hub_with_udp(dir: &DataDir, more: &str) -> anyhow::Result<(Agent, SocketAddr)> {
    let hub = Agent::hub_with_config(
        dir,
        &format!("[server]\nflow_udp = \"127.0.0.1:0\"\n{more}"),
    )
    .await?;
    hub.output.wait_for("flow hub: udp://", 1, PATIENCE).await?;
    let line = hub.output.matching("flow hub: udp://").remove(0);
    let addr = line
        .split("flow hub: udp://")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .context("no UDP address logged")?
        .parse()?;
    Ok((hub, addr))
}
