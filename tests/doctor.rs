//! `robot-agent doctor` as an operator runs it: a missing model named with its make target, a corrupt one, a busy
//! port, a running agent recognised, a certificate without the machine's addresses, and the exit status scripts
//! read (0 nothing wrong, 1 a problem).
//!
//! Build the binaries first: `cargo build --workspace --all-targets`.

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::time::Duration;

use agent_tests::binaries::Finished;
use agent_tests::{Agent, AgentOptions, DataDir, command, run};
use anyhow::Context;

/// The doctor's deadline: it hashes a few hundred MB of models and waits at most seconds for an answer per port.
const DEADLINE: Duration = Duration::from_secs(180);

/// The checkout's models folder (provisioned by `make test`).
fn checkout_models() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")
}

/// Runs `robot-agent doctor` on the data directory `dir` and the HTTP address `http`, with `extra` arguments.
async fn doctor(dir: &Path, http: &str, extra: &[&str]) -> anyhow::Result<Finished> {
    let mut cmd = command("robot-agent")?;
    cmd.arg("doctor")
        .arg("--data-dir")
        .arg(dir)
        .args(["--http", http])
        .args(extra);
    run(cmd, b"", DEADLINE).await
}

/// Runs `robot-agent doctor` on free ports with the models of `models`, so only the models and the folder are judged.
async fn doctor_on_models(dir: &Path, models: &Path) -> anyhow::Result<Finished> {
    let models = models.display().to_string();
    doctor(
        dir,
        ANY_PORT,
        &["--flow-tcp", ANY_PORT, "--models", &models],
    )
    .await
}

/// Free addresses: binding port 0 always finds the port free, so only the models and the folder are judged.
const ANY_PORT: &str = "127.0.0.1:0";

fn code(out: &Finished) -> Option<i32> {
    out.status.code()
}

fn line<'a>(out: &'a Finished, needle: &str) -> Option<&'a str> {
    out.stdout.lines().find(|l| l.contains(needle))
}

#[tokio::test]
async fn a_missing_model_is_named_with_its_path_and_make_target_and_exits_one() -> anyhow::Result<()>
{
    let dir = DataDir::new()?;
    let models = tempfile::tempdir()?;
    let out = doctor_on_models(dir.path(), models.path()).await?;
    assert_eq!(code(&out), Some(1), "{out:?}");
    let tiny = models.path().join("ggml-tiny.en.bin");
    let missing = line(&out, &format!("{} is missing", tiny.display()))
        .with_context(|| format!("no line names the missing model:\n{}", out.stdout))?;
    assert!(missing.starts_with("PROBLEM models:"), "{missing}");
    assert!(missing.contains("`make model`"), "{missing}");
    let llm =
        line(&out, "SmolLM2-135M-Instruct.Q4_1.gguf is missing").context("the language model")?;
    assert!(llm.contains("`make model-llm`"), "{llm}");
    Ok(())
}

#[tokio::test]
async fn a_corrupt_model_is_called_corrupt() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let models = tempfile::tempdir()?;
    // A copy of the real model with one byte flipped where it is provisioned, else a file that is no model.
    let mut bytes = std::fs::read(checkout_models().join("centerface.onnx"))
        .unwrap_or_else(|_| b"not a face detector".to_vec());
    let at = 100.min(bytes.len() - 1);
    bytes[at] ^= 0x01;
    let corrupt = models.path().join("centerface.onnx");
    std::fs::write(&corrupt, &bytes)?;
    let out = doctor_on_models(dir.path(), models.path()).await?;
    assert_eq!(code(&out), Some(1), "{out:?}");
    let found = line(&out, &format!("{} is corrupt", corrupt.display()))
        .with_context(|| format!("no line calls the model corrupt:\n{}", out.stdout))?;
    assert!(found.starts_with("PROBLEM models:"), "{found}");
    assert!(found.contains("`make model-face`"), "{found}");
    Ok(())
}

#[tokio::test]
async fn a_port_held_by_another_program_is_a_problem_with_its_fix() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    // Held, and answering nothing: not a robot-agent.
    let busy = TcpListener::bind("127.0.0.1:0")?;
    let addr = busy.local_addr()?.to_string();
    let out = doctor(dir.path(), &addr, &["--flow-tcp", ANY_PORT]).await?;
    assert_eq!(code(&out), Some(1), "{out:?}");
    let found = line(&out, &format!("HTTP {addr} is in use by something else"))
        .with_context(|| format!("no line names the busy port:\n{}", out.stdout))?;
    assert!(found.starts_with("PROBLEM ports:"), "{found}");
    assert!(found.contains("--http"), "{found}");
    drop(busy);
    Ok(())
}

#[tokio::test]
async fn the_ports_of_a_running_agent_are_recognised_as_its_own() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::start(&dir).await?;
    let flow_tcp = agent.flow_tcp.to_string();
    let unix = agent.flow_unix.display().to_string();
    let out = doctor(
        &agent.data_dir,
        &agent.http.to_string(),
        &["--flow-tcp", &flow_tcp, "--flow-unix", &unix],
    )
    .await?;
    for what in ["HTTP", "flow TCP", "flow Unix socket"] {
        let found = line(&out, &format!("ports: {what} "))
            .with_context(|| format!("no {what} line:\n{}", out.stdout))?;
        assert!(found.starts_with("ok"), "{found}");
        assert!(found.contains("in use by a running robot-agent"), "{found}");
    }
    let runs = line(&out, "agent: robot-agent runs").with_context(|| out.stdout.clone())?;
    assert!(runs.starts_with("ok"), "{runs}");
    // No satellite is connected: said, but only as a warning.
    assert!(
        line(&out, "no speech satellite").is_some_and(|l| l.starts_with("warning")),
        "{}",
        out.stdout
    );
    Ok(())
}

#[tokio::test]
async fn a_machine_with_its_models_and_free_ports_exits_zero() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    // The checkout's models, as `make test` provisions them.
    let out = doctor_on_models(dir.path(), &checkout_models()).await?;
    assert_eq!(code(&out), Some(0), "{out:?}");
    assert!(!out.stdout.contains("PROBLEM"), "{}", out.stdout);
    assert!(
        line(&out, "ggml-tiny.en.bin matches its checksum").is_some(),
        "{}",
        out.stdout
    );
    Ok(())
}

#[tokio::test]
async fn a_certificate_without_the_machines_addresses_is_named_with_the_fix() -> anyhow::Result<()>
{
    let dir = DataDir::new()?;
    // The agent makes its certificate at start; then it is stopped, and the certificate said to name only
    // `localhost`, as one made before the machine had its addresses.
    let agent = Agent::start_with(
        &dir,
        AgentOptions {
            program: Some("flow-hub"),
            args: vec!["--https".into()],
            ..Default::default()
        },
    )
    .await?;
    agent.kill9().await?;
    std::fs::write(dir.path().join("tls/names.txt"), "localhost")?;
    let out = doctor(dir.path(), ANY_PORT, &["--flow-tcp", ANY_PORT, "--https"]).await?;
    let found = line(&out, "tls:").with_context(|| format!("no tls line:\n{}", out.stdout))?;
    assert!(found.starts_with("warning tls:"), "{found}");
    assert!(
        found.contains("does not name") && found.contains("127.0.0.1"),
        "{found}"
    );
    assert!(!found.contains("localhost"), "{found}");
    assert!(found.contains("restart robot-agent"), "{found}");
    Ok(())
}
