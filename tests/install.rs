//! `make install` as an administrator runs it, into a temporary PREFIX so that nothing outside it is touched:
//! `scripts/install.sh` with the debug binaries already built (no user made, systemd not told), `systemd-analyze
//! verify` on the rendered units, the command line of the rendered `robot-agent.service` run by hand until it
//! serves `/healthz` and the page, a clean exit on SIGTERM, and `scripts/uninstall.sh` removing every file of the
//! install's manifest while keeping the configuration.
//!
//! Build the binaries first: `cargo build --workspace --all-targets`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use agent_tests::http::request;
use agent_tests::{DataDir, binary, free_port, run, until};
use anyhow::{Context, bail, ensure};
use tokio::process::Command;

/// The install's deadline: it copies the debug binaries, about a gigabyte, on a busy machine.
const DEADLINE: Duration = Duration::from_secs(300);
/// How long the installed agent may take to serve `/healthz` (a debug build starting on a busy machine).
const START: Duration = Duration::from_secs(120);

/// The repository root.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The temporary installation: the prefix, its configuration and unit folders, and the state folder `%S` stands
/// for.
struct Install {
    _dir: tempfile::TempDir,
    prefix: PathBuf,
    sysconf: PathBuf,
    units: PathBuf,
}

impl Install {
    fn new() -> anyhow::Result<Install> {
        let dir = tempfile::Builder::new().prefix("install-test-").tempdir()?;
        let at = |name: &str| dir.path().join(name);
        Ok(Install {
            prefix: at("prefix"),
            sysconf: at("etc"),
            units: at("units"),
            _dir: dir,
        })
    }

    /// `scripts/NAME` against this prefix, with the environment that keeps it inside the temporary folder.
    fn script(&self, name: &str) -> anyhow::Result<Command> {
        let bin_dir = binary("robot-agent")?
            .parent()
            .context("the binary has no folder")?
            .to_path_buf();
        // The checkout's models by a link where `make test` provisioned them (not a copy of hundreds of MB).
        let models = if root().join("models").is_dir() {
            "link"
        } else {
            "copy"
        };
        let mut cmd = Command::new("bash");
        cmd.arg(root().join("scripts").join(name))
            .arg(&self.prefix)
            .env("BIN_DIR", bin_dir)
            .env("SYSCONFDIR", &self.sysconf)
            .env("UNITDIR", &self.units)
            .env("MODELS", models)
            .env("CREATE_USER", "no")
            .env("SYSTEMCTL", "no")
            .env_remove("DESTDIR")
            .env_remove("ROLE")
            .env_remove("SERVICE_USER")
            .kill_on_drop(true);
        Ok(cmd)
    }

    fn manifest(&self) -> PathBuf {
        self.prefix.join("share/robot-agent/manifest")
    }
}

/// `KEY=value` lines of an environment file as systemd reads them (no shell, comments and blank lines skipped).
fn environment(text: &str) -> BTreeMap<String, String> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .filter_map(|l| l.split_once('='))
        .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
        .collect()
}

/// The value of the unit's first `KEY=` line.
fn unit_value<'a>(unit: &'a str, key: &str) -> Option<&'a str> {
    unit.lines()
        .find_map(|l| l.strip_prefix(key)?.strip_prefix('='))
}

/// An `ExecStart=` command line as systemd expands it: `%S` is the state folder, `$VAR` splits into words, `${VAR}`
/// stays one word. Anything else systemd would expand fails the test, so that a new specifier is not run literally.
fn expand(line: &str, state: &Path, env: &BTreeMap<String, String>) -> anyhow::Result<Vec<String>> {
    let mut words = Vec::new();
    for word in line.split_whitespace() {
        if let Some(name) = word.strip_prefix("${").and_then(|w| w.strip_suffix('}')) {
            words.push(env.get(name).cloned().unwrap_or_default());
        } else if let Some(name) = word.strip_prefix('$') {
            words.extend(
                env.get(name)
                    .map(|v| v.split_whitespace().map(str::to_string).collect::<Vec<_>>())
                    .unwrap_or_default(),
            );
        } else {
            let word = word.replace("%S", &state.display().to_string());
            ensure!(
                !word.contains('%') && !word.contains('$'),
                "the test does not know how systemd expands {word:?} in ExecStart"
            );
            words.push(word);
        }
    }
    Ok(words)
}

/// Sends SIGTERM to `pid`, as `systemctl stop` does.
fn terminate(pid: u32) -> anyhow::Result<()> {
    let status = std::process::Command::new("kill")
        .arg("-TERM")
        .arg(pid.to_string())
        .status()
        .context("running kill")?;
    ensure!(status.success(), "kill -TERM {pid} failed");
    Ok(())
}

/// Verifies the rendered units with `systemd-analyze verify` (which also checks that their programs exist), or says
/// why it cannot.
async fn verify_units(units: &Path) -> anyhow::Result<()> {
    let version = std::process::Command::new("systemd-analyze")
        .arg("--version")
        .stdout(Stdio::null())
        .status();
    if version.is_err() {
        println!(
            "skipped systemd-analyze verify: systemd-analyze is not installed on this machine"
        );
        return Ok(());
    }
    let mut cmd = Command::new("systemd-analyze");
    cmd.arg("verify")
        .arg(units.join("robot-agent.service"))
        .arg(units.join("llm-sat.service"))
        // An instance of the template, as `systemctl enable whisper-sat@1` makes it.
        .arg(units.join("whisper-sat@1.service"))
        .kill_on_drop(true);
    let out = run(cmd, b"", DEADLINE).await?;
    ensure!(
        out.success(),
        "systemd-analyze verify found fault with the rendered units ({}):\n{}{}",
        out.status,
        out.stdout,
        out.stderr
    );
    println!("systemd-analyze verify: the rendered units are sound");
    if !out.stderr.trim().is_empty() {
        println!("{}", out.stderr.trim_end());
    }
    Ok(())
}

#[tokio::test]
async fn an_install_into_a_temporary_prefix_runs_its_unit_command_and_uninstalls_cleanly()
-> anyhow::Result<()> {
    let install = Install::new()?;
    let out = run(install.script("install.sh")?, b"", DEADLINE).await?;
    let said = out.ok().context("scripts/install.sh")?;
    println!("{said}");

    let manifest = std::fs::read_to_string(install.manifest()).context("the install's manifest")?;
    let listed: Vec<(String, PathBuf)> = manifest
        .lines()
        .filter_map(|l| l.split_once(' '))
        .map(|(kind, path)| (kind.to_string(), PathBuf::from(path)))
        .collect();
    for wanted in [
        install.prefix.join("bin/robot-agent"),
        install.units.join("robot-agent.service"),
        install.sysconf.join("robot-agent/robot-agent.toml"),
    ] {
        ensure!(
            listed.iter().any(|(_, p)| *p == wanted),
            "the manifest does not list {}:\n{manifest}",
            wanted.display()
        );
    }
    for (_, path) in &listed {
        ensure!(
            path.starts_with(install.prefix.parent().context("the prefix has a folder")?),
            "{} was installed outside the temporary folder",
            path.display()
        );
    }

    verify_units(&install.units).await?;
    if Path::new("/run/systemd/system").exists() {
        println!(
            "skipped starting the units under the running systemd: that needs root and the user robot-agent, \
             and changes this machine"
        );
    } else {
        println!(
            "skipped starting the units under a real systemd: none runs here (/run/systemd/system is absent)"
        );
    }

    // The service's command line, as systemd would run it: its working directory, its environment file (with the
    // administrator's AGENT_ARGS giving free ports) and its state directory.
    let unit = std::fs::read_to_string(install.units.join("robot-agent.service"))?;
    let workdir = unit_value(&unit, "WorkingDirectory").context("no WorkingDirectory=")?;
    let env_file = unit_value(&unit, "EnvironmentFile").context("no EnvironmentFile=")?;
    let mut env = environment(&std::fs::read_to_string(env_file.trim_start_matches('-'))?);
    let (http_port, flow_port) = (free_port()?, free_port()?);
    env.insert(
        "AGENT_ARGS".into(),
        format!("--http 127.0.0.1:{http_port} --flow-tcp 127.0.0.1:{flow_port}"),
    );
    let state = DataDir::new()?;
    let exec = unit_value(&unit, "ExecStart").context("no ExecStart=")?;
    let words = expand(exec, state.path(), &env)?;
    let (program, args) = words.split_first().context("an empty ExecStart=")?;
    ensure!(
        Path::new(program).starts_with(&install.prefix),
        "ExecStart= runs {program}, not the installed binary"
    );
    let log_path = state.path().join("service.log");
    let log = std::fs::File::create(&log_path)?;
    let mut agent = Command::new(program)
        .args(args)
        .current_dir(workdir)
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .kill_on_drop(true)
        .spawn()
        .with_context(|| format!("starting {}", words.join(" ")))?;
    let log = || std::fs::read_to_string(&log_path).unwrap_or_default();
    let http: std::net::SocketAddr = format!("127.0.0.1:{http_port}").parse()?;

    let served = until(
        "the installed robot-agent to serve /healthz",
        START,
        async {
            loop {
                if let Some(status) = agent.try_wait()? {
                    bail!("the installed robot-agent exited at start ({status})");
                }
                if let Ok(answer) = request(http, "GET", "/healthz", &[]).await
                    && answer.status == 200
                {
                    return anyhow::Ok(answer);
                }
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        },
    )
    .await
    .and_then(|r| r)
    .with_context(log)?;
    assert_eq!(served.body, "ok");

    // The page, with the page token the service wrote into its state directory.
    let token = std::fs::read_to_string(state.path().join("robot-agent/page.token"))?;
    let bearer = format!("Bearer {}", token.trim());
    let page = request(http, "GET", "/", &[("Authorization", &bearer)]).await?;
    assert_eq!(page.status, 200, "{}\n{}", page.body, log());
    assert!(page.body.starts_with("<!doctype html>"), "{}", page.body);

    terminate(agent.id().context("the agent has exited")?)?;
    let status = until(
        "the installed robot-agent to exit after SIGTERM",
        START,
        agent.wait(),
    )
    .await?
    .context("waiting for robot-agent")?;
    assert!(status.success(), "exit after SIGTERM: {status}\n{}", log());

    let out = run(install.script("uninstall.sh")?, b"", DEADLINE).await?;
    println!("{}", out.ok().context("scripts/uninstall.sh")?);
    for (kind, path) in &listed {
        // `symlink_metadata`: the models are a link, which must go even though its target stays.
        let there = path.symlink_metadata().is_ok();
        if kind == "conf" {
            assert!(
                there,
                "uninstall removed the configuration {}",
                path.display()
            );
        } else {
            assert!(!there, "uninstall left {}", path.display());
        }
    }
    assert!(
        !install.prefix.join("share/robot-agent").exists(),
        "uninstall left the share folder"
    );
    Ok(())
}

#[test]
fn an_exec_start_line_is_expanded_as_systemd_does() -> anyhow::Result<()> {
    let env =
        environment("# a comment\nAGENT_ARGS=--http 0.0.0.0:8443 --https\n\nMODEL=/m/tiny.bin\n");
    let words = expand(
        "/p/bin/robot-agent --data-dir %S/robot-agent --model ${MODEL} $AGENT_ARGS $UNSET",
        Path::new("/var/lib"),
        &env,
    )?;
    assert_eq!(
        words,
        [
            "/p/bin/robot-agent",
            "--data-dir",
            "/var/lib/robot-agent",
            "--model",
            "/m/tiny.bin",
            "--http",
            "0.0.0.0:8443",
            "--https"
        ]
    );
    assert!(expand("/p/bin/x --name %H", Path::new("/s"), &env).is_err());
    Ok(())
}
