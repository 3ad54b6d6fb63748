//! Peak memory of a real `robot-agent` speaking with each engine: the server started as `make run` starts it
//! (brain and vision off, so that the speech engine is what differs), three replies said through `Agent.say`, then
//! the process's `VmHWM`.

use std::time::Duration;

use agent_contract::channels as ch;
use agent_tests::{Agent, DataDir, PATIENCE};
use anyhow::Context;
use serde_json::json;

/// The server's process: the one whose command line names its data directory.
fn agent_pid(agent: &Agent) -> anyhow::Result<u32> {
    let needle = agent.data_dir.to_string_lossy().into_owned();
    for entry in std::fs::read_dir("/proc")? {
        let entry = entry?;
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(cmdline) = std::fs::read(entry.path().join("cmdline")) else {
            continue;
        };
        let cmdline = String::from_utf8_lossy(&cmdline);
        if cmdline.contains("robot-agent") && cmdline.contains(&needle) {
            return Ok(pid);
        }
    }
    anyhow::bail!("no robot-agent process for {needle}")
}

fn peak_rss_mb(pid: u32) -> anyhow::Result<f64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let kb: f64 = status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        .context("no VmHWM")?;
    Ok(kb / 1024.0)
}

/// Peak RSS in MB of a robot-agent whose TTS engine is `engine` ("piper" or "espeak") after saying `replies`.
pub async fn agent_peak_rss_mb(engine: &str, replies: &[&str]) -> anyhow::Result<f64> {
    let dir = DataDir::new()?;
    let config = format!(
        "[modules.brain]\nenabled = false\n[modules.vision]\nenabled = false\n[modules.tts]\nengine = \"{engine}\"\n"
    );
    let agent = Agent::start_configured(&dir, &config, "tts: speaking on").await?;
    let client = agent.client("voice-bench").await?;
    let speech = client.subscribe(ch::SPEECH.name).await?;
    for text in replies {
        client
            .call(
                ch::SAY.name,
                json!({ "text": text }).to_string().into_bytes(),
                PATIENCE,
            )
            .await?;
        // Wait for the reply to be sent: the first chunk, then a pause in the stream.
        tokio::time::timeout(PATIENCE, speech.recv())
            .await?
            .context("Agent.speech closed")?;
        while tokio::time::timeout(Duration::from_millis(1500), speech.recv())
            .await
            .is_ok()
        {}
    }
    peak_rss_mb(agent_pid(&agent)?)
}
