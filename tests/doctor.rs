//! `robot-agent doctor` as an operator runs it: a missing model named with its make target, a corrupt one, a busy
//! port, a running agent recognised and its clock compared, a hub whose clock is off or untold, a certificate
//! without the machine's addresses, a page that would get no microphone (plain HTTP from another address), the
//! exit status scripts read (0 nothing wrong, 1 a problem), and `flow-hub doctor` without the agent's models.
//!
//! Build the binaries first: `cargo build --workspace --all-targets`.

use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use agent_tests::binaries::Finished;
use agent_tests::{Agent, AgentOptions, DataDir, PATIENCE, command, free_port, run};
use anyhow::Context;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// The doctor's deadline: it hashes a few hundred MB of models and waits at most seconds for an answer per port.
const DEADLINE: Duration = Duration::from_secs(180);

/// The checkout's models folder (provisioned by `make test`).
fn checkout_models() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")
}

/// Runs `robot-agent doctor` on the data directory `dir` and the HTTP address `http`, with `extra` arguments.
async fn doctor(dir: &Path, http: &str, extra: &[&str]) -> anyhow::Result<Finished> {
    doctor_of("robot-agent", dir, http, extra).await
}

/// Runs `program doctor` as [`doctor`] does.
async fn doctor_of(
    program: &str,
    dir: &Path,
    http: &str,
    extra: &[&str],
) -> anyhow::Result<Finished> {
    let mut cmd = command(program)?;
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

/// A small tmpfs mounted for one test, unmounted when dropped.
struct SmallDisk {
    path: PathBuf,
}

impl SmallDisk {
    /// Mounts a 4 MB tmpfs on a fresh folder, or says why it cannot (not root, no mount in this container).
    fn mount(parent: &Path) -> anyhow::Result<Result<SmallDisk, String>> {
        let path = parent.join("small-disk");
        std::fs::create_dir_all(&path)?;
        let out = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", "size=4m", "tmpfs"])
            .arg(&path)
            .output();
        Ok(match out {
            Ok(o) if o.status.success() => Ok(SmallDisk { path }),
            Ok(o) => Err(String::from_utf8_lossy(&o.stderr).trim().to_owned()),
            Err(e) => Err(e.to_string()),
        })
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg(&self.path)
            .status();
    }
}

#[tokio::test]
async fn a_full_disk_under_the_data_directory_is_a_problem_with_its_fix() -> anyhow::Result<()> {
    let parent = DataDir::new()?;
    let disk = match SmallDisk::mount(parent.path())? {
        Ok(disk) => disk,
        Err(why) => {
            println!("skipped: cannot mount a small tmpfs here ({why})");
            return Ok(());
        }
    };
    // Filled to the last block, as a disk a recording ran out of.
    let filler = vec![0u8; 64 * 1024];
    let mut file = std::fs::File::create(disk.path.join("filler"))?;
    while std::io::Write::write_all(&mut file, &filler).is_ok() {}
    drop(file);
    let out = doctor(&disk.path, ANY_PORT, &["--flow-tcp", ANY_PORT]).await?;
    assert_eq!(code(&out), Some(1), "{out:?}");
    let found = line(&out, "file system is full")
        .with_context(|| format!("no line calls the disk full:\n{}", out.stdout))?;
    assert!(found.starts_with("PROBLEM data:"), "{found}");
    assert!(found.contains("free space"), "{found}");
    Ok(())
}

#[tokio::test]
async fn the_ports_of_a_running_agent_are_recognised_as_its_own_and_its_clock_agrees()
-> anyhow::Result<()> {
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
    // The same clock on both ends: the offset lies within the round trip.
    let clock = line(&out, "clock:").with_context(|| out.stdout.clone())?;
    assert!(clock.starts_with("ok"), "{clock}");
    assert!(clock.contains("this machine's"), "{clock}");
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

/// A stand-in hub on a free port that answers every request with `ok`, telling its clock `skew_us` ahead of this
/// machine's, or not at all (`None`: a version from before the clock header). Ended with the returned handle.
async fn stand_in_hub(
    skew_us: Option<i64>,
) -> anyhow::Result<(SocketAddr, tokio::task::JoinHandle<()>)> {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let addr = listener.local_addr()?;
    let task = tokio::spawn(async move {
        while let Ok((mut stream, _)) = listener.accept().await {
            tokio::spawn(async move {
                // The request's head, within the tests' bound (the doctor sends it at once).
                let mut head = Vec::new();
                let mut chunk = [0u8; 1024];
                let read = tokio::time::timeout(PATIENCE, async {
                    while !head.windows(4).any(|w| w == b"\r\n\r\n") {
                        match stream.read(&mut chunk).await {
                            Ok(0) | Err(_) => return false,
                            Ok(n) => head.extend_from_slice(&chunk[..n]),
                        }
                    }
                    true
                })
                .await;
                if !matches!(read, Ok(true)) {
                    return;
                }
                let clock = skew_us.map_or_else(String::new, |skew| {
                    let now = SystemTime::now()
                        .duration_since(UNIX_EPOCH)
                        .map_or(0, |d| d.as_micros() as i64);
                    format!("X-Hub-Time-Us: {}\r\n", now + skew)
                });
                let answer = format!("HTTP/1.0 200 OK\r\nContent-Length: 2\r\n{clock}\r\nok");
                let _ = stream.write_all(answer.as_bytes()).await;
            });
        }
    });
    Ok((addr, task))
}

#[tokio::test]
async fn a_hub_whose_clock_is_3_s_ahead_is_a_problem_with_the_ntp_fix() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let (hub, task) = stand_in_hub(Some(3_000_000)).await?;
    let out = doctor(dir.path(), &hub.to_string(), &["--flow-tcp", ANY_PORT]).await?;
    task.abort();
    assert_eq!(code(&out), Some(1), "{out:?}");
    let found = line(&out, "clock:").with_context(|| format!("no clock line:\n{}", out.stdout))?;
    assert!(found.starts_with("PROBLEM clock:"), "{found}");
    assert!(found.contains("ahead of this machine's"), "{found}");
    assert!(
        found.contains("chrony") && found.contains("timesyncd"),
        "{found}"
    );
    Ok(())
}

#[tokio::test]
async fn a_hub_that_does_not_tell_its_time_is_a_warning_that_the_skew_cannot_be_checked()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let (hub, task) = stand_in_hub(None).await?;
    let out = doctor(dir.path(), &hub.to_string(), &["--flow-tcp", ANY_PORT]).await?;
    task.abort();
    let found = line(&out, "clock:").with_context(|| format!("no clock line:\n{}", out.stdout))?;
    assert!(found.starts_with("warning clock:"), "{found}");
    assert!(found.contains("cannot be checked"), "{found}");
    Ok(())
}

#[tokio::test]
async fn a_page_opened_over_plain_http_from_another_address_is_a_problem_with_the_https_fix()
-> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let lan = format!("0.0.0.0:{}", free_port()?);
    // Without --from: plain HTTP beyond loopback is only a warning.
    let out = doctor(dir.path(), &lan, &["--flow-tcp", ANY_PORT]).await?;
    let page = line(&out, "page:").with_context(|| format!("no page line:\n{}", out.stdout))?;
    assert!(page.starts_with("warning page:"), "{page}");
    assert!(page.contains("no microphone"), "{page}");
    assert!(page.contains("--from"), "{page}");
    // From another machine's browser: a problem, and the exit status says so.
    let out = doctor(
        dir.path(),
        &lan,
        &["--flow-tcp", ANY_PORT, "--from", "192.168.1.20"],
    )
    .await?;
    assert_eq!(code(&out), Some(1), "{out:?}");
    // (192.168.1.20 is probably none of this machine's addresses either: another line, a warning, says so.)
    let page = line(&out, "is not a secure context")
        .with_context(|| format!("no line about the secure context:\n{}", out.stdout))?;
    assert!(page.starts_with("PROBLEM page:"), "{page}");
    assert!(page.contains("--https"), "{page}");
    // From a browser on the machine itself: fine.
    let out = doctor(
        dir.path(),
        &lan,
        &["--flow-tcp", ANY_PORT, "--from", "localhost"],
    )
    .await?;
    let page = line(&out, "page:").with_context(|| format!("no page line:\n{}", out.stdout))?;
    assert!(page.starts_with("ok"), "{page}");
    assert!(page.contains("is a secure context"), "{page}");
    Ok(())
}

#[tokio::test]
async fn flow_hubs_doctor_runs_the_hub_checks_without_the_agents_models() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let out = doctor_of("flow-hub", dir.path(), ANY_PORT, &["--flow-tcp", ANY_PORT]).await?;
    assert_eq!(code(&out), Some(0), "{out:?}");
    assert!(line(&out, "ports: HTTP").is_some(), "{}", out.stdout);
    assert!(line(&out, "models:").is_none(), "{}", out.stdout);
    // The models option is robot-agent's: the bare hub does not take it.
    let refused = doctor_of("flow-hub", dir.path(), ANY_PORT, &["--models", "/m"]).await?;
    assert_eq!(code(&refused), Some(2), "{refused:?}");
    Ok(())
}
