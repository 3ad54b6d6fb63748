//! Wiring: listeners, modules and the shutdown sequence around the shared state (`shared.rs`).

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context;
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tracing::info;

use crate::admission::Admission;
use crate::config::Config;
use crate::http::access::{self, Access};
use crate::hub::{Hub, HubLimits, OutboxLimits, ShmSettings};
use crate::metrics::Metrics;
use crate::module::Module;
use crate::net::IoRuntime;
use crate::pairdb::PairDb;
use crate::pulse::PulseHub;
pub use crate::shared::Shared;
use crate::tokens::Tokens;

/// A started server: its bound addresses and a handle to stop it.
#[derive(Debug)]
pub struct RunningServer {
    pub http: SocketAddr,
    /// The page's address with its credential (what the operator opens).
    pub page_url: String,
    /// With `[http] tls`: the certificate's SHA-256 fingerprint, to compare on the browser's warning page.
    pub tls_fingerprint: Option<String>,
    pub flow_tcp: Option<SocketAddr>,
    /// The UDP edge's address (`server.flow_udp`), when on.
    pub flow_udp: Option<SocketAddr>,
    pub flow_unix: Option<PathBuf>,
    pub shared: Arc<Shared>,
    tasks: Vec<JoinHandle<()>>,
    /// The modules' tasks, stopped first at shutdown.
    module_tasks: Vec<JoinHandle<()>>,
    io: IoRuntime,
}

/// What an application brings to the hub: its in-server modules (in start order, each switched by its
/// `[modules.NAME]` section) and its HTTP routes, served behind the same access gate as the hub's own. The
/// shutdown signal is the caller's, so that parts it built before the start (a page link) see it too.
pub struct Application {
    pub modules: Vec<Box<dyn Module>>,
    pub routes: axum::Router,
    pub shutdown: watch::Sender<bool>,
}

impl std::fmt::Debug for Application {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names: Vec<&str> = self.modules.iter().map(|m| m.name()).collect();
        f.debug_struct("Application")
            .field("modules", &names)
            .finish_non_exhaustive()
    }
}

impl Default for Application {
    /// The bare hub: no modules, no routes of its own.
    fn default() -> Self {
        Application {
            modules: Vec::new(),
            routes: axum::Router::new(),
            shutdown: watch::channel(false).0,
        }
    }
}

/// Opens the data directory, binds every listener and starts the application's modules.
pub async fn start(config: Config, app: Application) -> anyhow::Result<RunningServer> {
    let Application {
        modules,
        routes,
        shutdown,
    } = app;
    // Every module's section is checked before anything is bound or created, so a bad value stops the server at
    // start with the file, the key and the reason (a `ConfigError` the binary reports as such).
    let names: Vec<&str> = modules.iter().map(|m| m.name()).collect();
    config.check_module_names(&names)?;
    let mut modules: Vec<Box<dyn Module>> = modules
        .into_iter()
        .filter(|m| config.module_enabled(m.name()))
        .collect();
    // The federation is the hub's own module, switched by `[federation]`; its Zenoh session opens here so that an
    // endpoint it cannot listen on stops the start.
    if config.federation.enabled {
        let federation = crate::federation::Federation::open(&config).await?;
        modules.insert(0, Box::new(federation));
    }
    for m in &modules {
        m.check(&config.module(m.name()))
            .map_err(|e| config.module_error(m.name(), &format!("{e:#}")))?;
    }
    // Every descriptor the hard limit allows: each satellite, page and stranger holds one.
    let fd_limit = crate::net::descriptors::raise_limit();
    let data_dir = config.server.data_dir.clone();
    std::fs::create_dir_all(&data_dir)
        .with_context(|| format!("creating data dir {}", data_dir.display()))?;
    let tokens = Tokens::load_or_create(&data_dir).context("reading or creating tokens")?;
    let db_path = data_dir.join("pairs.redb");
    let pairdb = tokio::task::spawn_blocking(move || PairDb::open(&db_path))
        .await?
        .context("opening the pair database")?;
    let h = &config.hub;
    let limits = HubLimits {
        outbox: OutboxLimits {
            lane_msgs: h.subscriber_queue,
            lane_bytes: h.subscriber_queue_bytes,
            control_msgs: h.control_queue,
        },
        service_inflight: h.service_inflight,
        max_channels: crate::hub::MAX_CHANNELS,
    };
    let pulses = Arc::new(PulseHub::new(
        Duration::from_millis(config.ticks.fast_ms),
        Duration::from_millis(config.ticks.slow_ms),
    ));
    let shm = ShmSettings {
        enabled: h.shm,
        threshold: h.shm_threshold,
        slots: h.shm_slots,
        per_channel: h.shm_segments_per_channel,
        held: h.shm_held,
    };
    let hub = Arc::new(Hub::with_shm(limits, shm));
    let shared = Arc::new(Shared {
        metrics: Arc::new(Metrics::new(hub.clone())),
        hub,
        pairdb: Arc::new(pairdb),
        tokens,
        pulses: pulses.clone(),
        admission: Arc::new(Admission::new(
            config.hub.max_unauthenticated,
            config.hub.max_unauthenticated_per_address,
        )),
        shutdown,
        modules_stop: watch::channel(false).0,
        telemetry: flow_telemetry::Telemetry::start(
            &service_name(),
            Some(("[telemetry] otlp", &config.telemetry.otlp)),
        )?,
        reports: Mutex::new(BTreeMap::new()),
        config,
    });
    let mut tasks = Vec::new();
    tasks.push(tokio::spawn(pulses.run(
        shared.hub.clone(),
        shared.metrics.clone(),
        shared.shutdown.subscribe(),
    )));

    // Socket connections are served on the hub's own I/O runtime; listeners are created inside its context so
    // that they, and every connection they accept, belong to its reactor.
    let io =
        IoRuntime::start(shared.config.hub.io_threads).context("starting the hub I/O runtime")?;
    let flow_tcp = if shared.config.server.flow_tcp.is_empty() {
        None
    } else {
        let addr = &shared.config.server.flow_tcp;
        let std_listener = std::net::TcpListener::bind(addr)
            .and_then(|l| l.set_nonblocking(true).map(|()| l))
            .with_context(|| format!("binding flow TCP {addr}"))?;
        let listener = {
            let _io = io.handle().enter();
            TcpListener::from_std(std_listener)
                .with_context(|| format!("binding flow TCP {addr}"))?
        };
        let bound = listener.local_addr()?;
        tasks.push(
            io.handle()
                .spawn(crate::net::tcp::accept_loop(listener, shared.clone())),
        );
        Some(bound)
    };
    let flow_udp = if shared.config.server.flow_udp.is_empty() {
        None
    } else {
        let addr = &shared.config.server.flow_udp;
        let std_socket = std::net::UdpSocket::bind(addr)
            .and_then(|s| s.set_nonblocking(true).map(|()| s))
            .with_context(|| format!("binding flow UDP {addr}"))?;
        let socket = {
            let _io = io.handle().enter();
            tokio::net::UdpSocket::from_std(std_socket)
                .and_then(flow::transport::udp::batch::BatchSocket::new)
                .with_context(|| format!("binding flow UDP {addr}"))?
        };
        let bound = socket.socket().local_addr()?;
        tasks.push(
            io.handle()
                .spawn(crate::net::udp::serve(socket, shared.clone())),
        );
        info!("flow hub: udp://{bound}");
        Some(bound)
    };
    let flow_unix = match shared.config.unix_socket() {
        None => None,
        Some(path) => {
            let listener = {
                let _io = io.handle().enter();
                crate::net::unix::bind(&path)
                    .with_context(|| format!("binding unix socket {}", path.display()))?
            };
            tasks.push(io.handle().spawn(crate::net::unix::accept_loop(
                listener,
                path.clone(),
                shared.clone(),
            )));
            Some(path)
        }
    };
    if !shared.config.hub.serial.is_empty() {
        tasks.push(
            io.handle()
                .spawn(crate::net::serial::serve_lines(shared.clone())),
        );
    }
    let http_addr = &shared.config.server.http;
    let listener = TcpListener::bind(http_addr)
        .await
        .with_context(|| format!("binding HTTP {http_addr}"))?;
    let http = listener.local_addr()?;
    let tls = crate::http::tls::load(&shared.config).context("setting up HTTPS ([http] tls)")?;
    let h = &shared.config.http;
    let access = Arc::new(
        Access::new(
            shared.tokens.clone(),
            http.port(),
            Duration::from_secs(h.cookie_days * 24 * 3600),
            h.allowed_hosts.clone(),
            h.open_on_loopback,
        )
        .over_tls(tls.is_some()),
    );
    let scheme = if tls.is_some() { "https" } else { "http" };
    let page_url = if access.is_open() {
        format!("{scheme}://{http}/")
    } else {
        format!("{scheme}://{http}/?token={}", shared.tokens.page())
    };
    let tls_fingerprint = tls.as_ref().map(|t| t.fingerprint.clone());
    let router = crate::http::app(shared.clone())
        .merge(routes)
        .layer(axum::middleware::from_fn_with_state(access, access::gate));
    tasks.push(tokio::spawn(crate::http::serve::run(
        listener,
        tls,
        router,
        shared.clone(),
    )));
    let mut module_tasks = Vec::new();
    for module in modules {
        module_tasks.push(crate::module::spawn(shared.clone(), module).await?);
    }
    info!(%http, ?flow_tcp, ?flow_udp, ?flow_unix, ?fd_limit, "robot-agent is up");
    Ok(RunningServer {
        http,
        page_url,
        tls_fingerprint,
        flow_tcp,
        flow_udp,
        flow_unix,
        shared,
        tasks,
        module_tasks,
        io,
    })
}

impl RunningServer {
    /// Stops the modules, then tells clients goodbye and stops the listeners, and waits for them.
    ///
    /// Modules go first, while the hub still serves every connection: a module's last work may need the hub (the
    /// recorder reads what the hub had accepted before the stop) and may need what satellites still send. Only then
    /// are the outboxes closed, so nothing the hub acknowledged before the stop is lost to a module.
    pub async fn shutdown(self) {
        info!("shutting down");
        self.shared.modules_stop.send_replace(true);
        join_within(self.module_tasks, "a module").await;
        self.shared.hub.shutdown("server shutting down");
        self.shared.shutdown.send_replace(true);
        join_within(self.tasks, "a task").await;
        // The listeners have waited for their connections; what is left on the I/O runtime ends here.
        self.io.stop().await;
        // redb commits every acknowledged write durably; nothing is left to flush.
        info!("stopped");
    }
}

/// Waits for each task to end, at most 5 s each, and logs one that does not.
async fn join_within(tasks: Vec<JoinHandle<()>>, what: &str) {
    for task in tasks {
        if tokio::time::timeout(Duration::from_secs(5), task)
            .await
            .is_err()
        {
            tracing::warn!("{what} did not stop within 5 s");
        }
    }
}

/// The `service.name` of this process's spans: the binary's name (`robot-agent`, `flow-hub`).
fn service_name() -> String {
    std::env::current_exe()
        .ok()
        .and_then(|exe| exe.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .filter(|name| !name.is_empty())
        .unwrap_or_else(|| "robot-agent".to_owned())
}
