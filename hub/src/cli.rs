//! The command line of the hub's binaries (`flow-hub`, `robot-agent`): options, the configuration, logging, the
//! application's modules and routes, and a clean shutdown on Ctrl-C or SIGTERM. Configuration errors exit with
//! status 2 and name the file, the key and the reason. `doctor` checks the machine instead of serving
//! (`crate::doctor`), with the checks a binary adds ([`main_with`]).

use std::path::PathBuf;

use anyhow::Context;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use tracing_subscriber::EnvFilter;

use crate::config::{Config, ConfigError};
use crate::doctor::Check;
use crate::server::Application;

/// Options common to every hub binary.
#[derive(Debug, Parser)]
#[command(version)]
pub struct Args {
    #[command(subcommand)]
    command: Option<Command>,
    /// Configuration file layered over the embedded defaults.
    #[arg(long, global = true)]
    config: Option<PathBuf>,
    /// HTTP address (UI, /api, /flow WebSocket).
    #[arg(long, global = true)]
    http: Option<String>,
    /// FlowProtocol TCP address ("" disables).
    #[arg(long, global = true)]
    flow_tcp: Option<String>,
    /// FlowProtocol Unix socket path ("" disables).
    #[arg(long, global = true)]
    flow_unix: Option<String>,
    /// Serve the page over HTTPS (`[http] tls`): with a certificate made for this machine, unless --tls-cert and
    /// --tls-key name one.
    #[arg(long, global = true)]
    https: bool,
    /// PEM certificate chain for HTTPS (with --tls-key).
    #[arg(long, value_name = "FILE", requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// PEM private key for HTTPS (with --tls-cert).
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// Directory for tokens, the pair database and the socket.
    #[arg(long, global = true)]
    data_dir: Option<PathBuf>,
    /// Record every stream channel into this MCAP file from start to shutdown (the recorder module,
    /// `[modules.recorder] file`; robot-agent has it, the bare hub records with `flowctl record`).
    #[arg(long, value_name = "FILE")]
    record: Option<PathBuf>,
}

/// What to do instead of serving.
#[derive(Debug, Subcommand)]
enum Command {
    /// Check this machine: ports, the data directory, the certificate, the page's secure context, the clock,
    /// satellites.
    ///
    /// Checks before or while the hub runs: the configured ports, the data directory's room, the HTTPS certificate's
    /// names, whether the page gets the microphone and camera (a secure context), this machine's clock against the
    /// hub's at the HTTP address (on a satellite's machine: --http ROBOT:PORT) and the connected satellites, after
    /// the binary's own checks. One line per finding, with its fix. Exit status: 0 when no problem was found
    /// (warnings included), 1 when one was, 2 for an invalid configuration.
    Doctor {
        /// The address or host name a browser will open the page by (`robot.local`, `192.168.1.20`): checks that
        /// the page is a secure context there, so that it gets the microphone and camera.
        #[arg(long, value_name = "ADDRESS")]
        from: Option<String>,
    },
}

/// Runs the binary `name` (described by `about`) with the application `build` makes from the configuration, until
/// Ctrl-C or SIGTERM; exits the process on error. Its `doctor` runs the hub's checks.
pub async fn main(
    name: &'static str,
    about: &'static str,
    build: fn(&Config) -> anyhow::Result<Application>,
) {
    main_with(name, about, build, &[]).await;
}

/// [`main`], with `checks` run by `doctor` before the hub's (the binary's own parts: robot-agent's models), their
/// options added to the subcommand.
pub async fn main_with(
    name: &'static str,
    about: &'static str,
    build: fn(&Config) -> anyhow::Result<Application>,
    checks: &[&dyn Check],
) {
    let command = Args::command()
        .name(name)
        .about(about)
        .mut_subcommand("doctor", |doctor| {
            checks.iter().fold(doctor, |d, check| check.arguments(d))
        });
    let matches = command.get_matches();
    let args = match Args::from_arg_matches(&matches) {
        Ok(a) => a,
        Err(e) => e.exit(),
    };
    if let Some(Command::Doctor { from }) = &args.command {
        let options = crate::doctor::Options {
            from: from.clone(),
            args: matches
                .subcommand_matches("doctor")
                .cloned()
                .unwrap_or_default(),
        };
        let code = match doctor(&args, &options, checks) {
            Ok(code) => code,
            Err(e) => exit_code(name, &e),
        };
        std::process::exit(code);
    }
    if let Err(e) = run(name, args, build).await {
        std::process::exit(exit_code(name, &e));
    }
}

/// Reports an error and gives the exit status for it: 2 for an invalid configuration, 1 otherwise.
fn exit_code(name: &str, e: &anyhow::Error) -> i32 {
    // A module's section is checked at start: report it like any other configuration error.
    if let Some(config) = e.downcast_ref::<ConfigError>() {
        eprintln!("{name}: invalid configuration: {config}");
        return 2;
    }
    eprintln!("{name}: {e:#}");
    1
}

/// `doctor`: prints the findings on stdout and returns the exit status.
fn doctor(
    args: &Args,
    options: &crate::doctor::Options,
    checks: &[&dyn Check],
) -> anyhow::Result<i32> {
    let config = configure(args)?;
    let findings = crate::doctor::examine(&config, options, checks);
    for finding in &findings {
        println!("{finding}");
    }
    Ok(crate::doctor::exit_code(&findings))
}

/// The configuration: the file over the embedded defaults, with the command line's addresses, data directory and
/// TLS over both.
fn configure(args: &Args) -> anyhow::Result<Config> {
    let mut config = Config::load(args.config.as_deref())?;
    if let Some(v) = &args.http {
        config.server.http.clone_from(v);
    }
    if let Some(v) = &args.flow_tcp {
        config.server.flow_tcp.clone_from(v);
    }
    if let Some(v) = &args.flow_unix {
        config.server.flow_unix.clone_from(v);
    }
    if let Some(v) = &args.data_dir {
        config.server.data_dir.clone_from(v);
    }
    if let (Some(cert), Some(key)) = (&args.tls_cert, &args.tls_key) {
        config.http.tls = "files".into();
        config.http.tls_cert = cert.display().to_string();
        config.http.tls_key = key.display().to_string();
    } else if args.https && !config.http.tls_on() {
        config.http.tls = "self-signed".into();
    }
    if let Some(file) = &args.record {
        config.modules.entry("recorder".into()).or_default().insert(
            "file".into(),
            toml::Value::String(file.display().to_string()),
        );
    }
    Ok(config)
}

async fn run(
    name: &str,
    args: Args,
    build: fn(&Config) -> anyhow::Result<Application>,
) -> anyhow::Result<()> {
    let config = configure(&args)?;
    let filter =
        EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(&config.server.log));
    crate::log::init(filter);

    let app = build(&config)?;
    if args.record.is_some()
        && !app
            .modules
            .iter()
            .any(|m| m.name() == "recorder" && config.module_enabled("recorder"))
    {
        anyhow::bail!(
            "--record needs the recorder module, which {name} does not run (record with `flowctl record`, or \
             enable [modules.recorder])"
        );
    }
    // The stop signals are taken before the server starts: it answers /healthz while its modules are still starting
    // (the Piper voice's checks take a second), and a SIGTERM then (systemd stopping a unit as it comes up, the
    // install test) killed it with the default action instead of a clean shutdown.
    let stop = StopSignals::new()?;
    let server = crate::start(config, app)
        .await
        .with_context(|| format!("starting {name}"))?;
    println!("{name} ready: open {}", server.page_url);
    if let Some(fp) = &server.tls_fingerprint {
        println!("  certificate SHA-256 {fp}");
        println!(
            "  (the browser warns about a certificate it does not know: compare this fingerprint, then accept it)"
        );
    }
    if server.http.ip().is_unspecified() {
        println!(
            "  (from another machine, put this machine's address in place of {})",
            server.http.ip()
        );
    }
    if let Some(tcp) = server.flow_tcp {
        println!("flow hub: tcp://{tcp}  ws://{}/flow", server.http);
    }
    if let Some(unix) = &server.flow_unix {
        println!("flow hub: unix:{}", unix.display());
    }
    stop.wait().await;
    server.shutdown().await;
    Ok(())
}

/// SIGTERM and SIGINT (Ctrl-C), handled from the moment this is made.
struct StopSignals {
    term: tokio::signal::unix::Signal,
    interrupt: tokio::signal::unix::Signal,
}

impl StopSignals {
    fn new() -> anyhow::Result<Self> {
        use tokio::signal::unix::{SignalKind, signal};
        Ok(StopSignals {
            term: signal(SignalKind::terminate()).context("handling SIGTERM")?,
            interrupt: signal(SignalKind::interrupt()).context("handling SIGINT")?,
        })
    }

    /// Waits for either.
    async fn wait(mut self) {
        tokio::select! {
            _ = self.term.recv() => {}
            _ = self.interrupt.recv() => {}
        }
    }
}
