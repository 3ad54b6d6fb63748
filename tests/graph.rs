//! The live graph page (`/graph`) against a running agent as `make run` starts it (every module on), with a real
//! whisper-sat and a flowctl subscriber: reached from the main page's link, it draws every one of them as a node and
//! the channels between them as edges, and keeps updating. Saves `artifacts/graph.png`.

use std::time::Duration;

use agent_contract::channels::TRANSCRIPT;
use agent_tests::browser_chromium::{Chromium, Devices};
use agent_tests::{Agent, DataDir, Satellite};
use serde_json::Value;

/// Two shared cores, Chromium and whisper.cpp starting: generous, never a measurement.
const PATIENCE: Duration = Duration::from_secs(120);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_graph_page_shows_the_satellites_modules_and_channels_of_a_running_agent()
-> anyhow::Result<()> {
    let data = DataDir::new()?;
    let agent = Agent::start(&data).await?;
    agent
        .output
        .wait_for("module started", 6, agent_tests::PATIENCE)
        .await?;
    let _ears = Satellite::start(&agent, "graph-ears").await?;
    let mut echo = agent.flowctl()?;
    echo.arg("--login")
        .arg("graph-watcher")
        .arg("echo")
        .arg(TRANSCRIPT.name)
        .stdout(std::process::Stdio::null())
        .kill_on_drop(true);
    let _watcher = echo.spawn()?;

    let browser = Chromium::launch_with(&Devices::Absent).await?;
    let tab = browser.open(&agent.page_url("")).await?;
    browser
        .wait_for(
            &tab,
            "document.querySelector('a[href=\"/graph\"]') !== null",
            PATIENCE,
        )
        .await?;
    browser
        .eval(
            &tab,
            "document.querySelector('a[href=\"/graph\"]').click(), true",
        )
        .await?;
    // Every node we started, and at least two updates, so the page is live rather than a one-off picture.
    let wanted = [
        "graph-ears",
        "graph-watcher",
        "vision",
        "brain",
        "tts",
        "browser",
        "observer",
    ];
    let check = format!(
        "location.pathname === '/graph' && window.graphDebug && graphDebug.updates >= 2 && \
         {:?}.every((n) => graphDebug.nodes.includes(n))",
        wanted
    );
    browser.wait_for(&tab, &check, PATIENCE).await?;
    let edges: Vec<Value> = serde_json::from_value(browser.eval(&tab, "graphDebug.edges").await?)?;
    let has = |channel: &str, to: &str| {
        edges
            .iter()
            .any(|e| e["channel"] == channel && e["to"] == to)
    };
    assert!(
        has(TRANSCRIPT.name, "graph-watcher"),
        "no transcript edge to flowctl: {edges:?}"
    );
    assert!(
        has(TRANSCRIPT.name, "brain"),
        "no transcript edge to the brain: {edges:?}"
    );
    // The satellite relays transcripts: it is the producer of those edges. (No page holds the microphone, so the
    // microphone channel, which the satellite waits for, does not exist yet.)
    assert!(
        edges
            .iter()
            .any(|e| e["channel"] == TRANSCRIPT.name && e["from"] == "graph-ears"),
        "the satellite does not publish transcripts: {edges:?}"
    );
    let error = browser.eval(&tab, "graphDebug.error").await?;
    assert_eq!(error, "", "the page refused a graph");
    // Drawn, not only counted: one SVG group per node and per curve (channels between the same two share one).
    let drawn = browser
        .eval(
            &tab,
            "[document.querySelectorAll('#graph .node').length, document.querySelectorAll('#graph .edge').length]",
        )
        .await?;
    assert!(drawn[0].as_u64() >= Some(wanted.len() as u64), "{drawn}");
    let curves = browser.eval(&tab, "graphDebug.curves").await?;
    assert_eq!(drawn[1].as_u64(), curves.as_u64(), "{drawn}");
    let png = browser.screenshot(&tab).await?;
    std::fs::create_dir_all(agent_tests::artifacts_dir())?;
    std::fs::write(agent_tests::artifacts_dir().join("graph.png"), &png)?;
    browser.quit().await;
    Ok(())
}
