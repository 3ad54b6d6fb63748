//! The browser link: serves the embedded page, accepts its WebSocket, runs the microphone/camera role, moves media
//! into hub channels and hub channels to the page, and runs the `Agent.video.y` and `Agent.audio.fft` modules.
//!
//! The protocol is documented in `docs/browser-link.md`. Everything here talks to the hub through one
//! `flow::Client`, like any satellite, so a robot body or a test can stand in for the browser.

mod assets;
mod audio_fft;
mod downlink;
mod luma;
mod origin;
mod pacing;
mod role;
mod routes;
mod session;
mod socket;
mod spectrum;
mod uplink;
mod video_y;
mod wire;

use std::collections::HashMap;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex, MutexGuard};

use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;

pub use origin::OriginPolicy;
pub use session::SessionLimits;

use role::{PageId, RoleBoard};
use session::SessionStore;

/// Channel names this module reads or writes (the contract in the project README).
pub mod channels {
    pub const AUDIO: &str = "Agent.audio";
    pub const VIDEO: &str = "Agent.video";
    pub const VIDEO_Y: &str = "Agent.video.y";
    pub const AUDIO_FFT: &str = "Agent.audio.fft";
    pub const CTRL: &str = "Agent.ctrl";
    pub const AVATAR: &str = "Agent.avatar";
    pub const SPEECH: &str = "Agent.speech";
    pub const DETECTIONS: &str = "Agent.detections";
    pub const RULES: &str = "Agent.rules";
}

/// Settings of the browser link (the `[browser]` table of the config).
#[derive(Debug, Clone)]
pub struct BrowserConfig {
    /// Host names besides loopback names and IP literals that the page may be opened under.
    pub extra_hosts: Vec<String>,
    /// JPEG quality of `Agent.video.y` frames.
    pub y_quality: u8,
    /// Samples between two spectra on `Agent.audio.fft` (1024 = no overlap).
    pub fft_hop: usize,
    pub sessions: SessionLimits,
}

impl Default for BrowserConfig {
    fn default() -> Self {
        BrowserConfig { extra_hosts: Vec::new(), y_quality: 80, fft_hop: spectrum::FFT_SIZE, sessions: SessionLimits::default() }
    }
}

/// What one page's socket task is told by others.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Notice {
    /// The holder left and this page, next in line, now holds the role.
    Granted,
}

/// State shared by the HTTP handlers and every page's socket task.
#[derive(Debug)]
struct Shared {
    client: flow::Client,
    config: BrowserConfig,
    origin: OriginPolicy,
    sessions: Mutex<SessionStore>,
    roles: Mutex<RoleBoard>,
    pages: Mutex<HashMap<PageId, mpsc::Sender<Notice>>>,
    next_page: AtomicU64,
    shutdown: watch::Receiver<bool>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic while holding one of these locks leaves plain data behind (no invariants span a panic), so the
    // poisoned state is still usable.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// The browser link, ready to be mounted into the HTTP app.
#[derive(Debug, Clone)]
pub struct BrowserLink {
    shared: Arc<Shared>,
}

impl BrowserLink {
    /// `client` is the link's own hub connection (its login name owns `Agent.audio`/`Agent.video` while a page
    /// holds the role); `shutdown` turning true closes every page socket.
    pub fn new(client: flow::Client, config: BrowserConfig, shutdown: watch::Receiver<bool>) -> Self {
        let origin = OriginPolicy { extra_hosts: config.extra_hosts.clone() };
        let sessions = Mutex::new(SessionStore::new(config.sessions));
        BrowserLink {
            shared: Arc::new(Shared {
                client,
                config,
                origin,
                sessions,
                roles: Mutex::new(RoleBoard::default()),
                pages: Mutex::new(HashMap::new()),
                next_page: AtomicU64::new(1),
                shutdown,
            }),
        }
    }

    /// Routes: `/` and the page's assets, `POST /api/session`, `GET /link` (the WebSocket).
    pub fn router(&self) -> axum::Router {
        routes::router(self.shared.clone())
    }

    /// Starts the `Agent.video.y` and `Agent.audio.fft` modules on `client` (they work while someone subscribes).
    pub fn spawn_modules(client: flow::Client, config: &BrowserConfig, shutdown: watch::Receiver<bool>) -> Vec<JoinHandle<()>> {
        vec![
            tokio::spawn(video_y::run(client.clone(), config.y_quality, shutdown.clone())),
            tokio::spawn(audio_fft::run(client, config.fft_hop, shutdown)),
        ]
    }
}
