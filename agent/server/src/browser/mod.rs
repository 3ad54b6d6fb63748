//! The browser link: serves the embedded page, accepts its WebSocket, runs the microphone/camera role, and moves
//! media into hub channels and hub channels to the page. (The `Agent.video.y` and `Agent.audio.fft` modules that
//! derive channels from the page's media are modules like the others, in `crate::modules`.)
//!
//! The protocol is documented in `docs/browser-link.md`. Everything here talks to the hub through one
//! `flow::Client`, like any satellite, so a robot body or a test can stand in for the browser.

mod assets;
mod downlink;
mod links;
mod pacing;
mod role;
mod routes;
mod session;
mod socket;
mod state;
mod uplink;
mod wire;

use std::collections::HashMap;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use serde::Deserialize;
use tokio::sync::watch;

use flow_hub::config::Config;
use flow_hub::module::{Module, ModuleContext, ModuleFuture};

use links::LinkBoard;
use role::RoleBoard;
use session::{SessionLimits, SessionStore};
use state::Shared;

/// Settings of the browser link, from `[modules.browser]` (and `[modules.video_y]` / `[modules.audio_fft]`).
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BrowserConfig {
    /// Whether the link runs at all (`false`: the page is still served, its WebSocket is refused).
    pub enabled: bool,
    /// Seconds a fresh session token may wait for its WebSocket.
    pub session_ttl_s: u64,
    /// Page sockets open at once, in total.
    pub max_links: usize,
    /// Page sockets open at once under one credential (one browser's session cookie).
    pub max_links_per_session: usize,
}

impl Default for BrowserConfig {
    fn default() -> Self {
        BrowserConfig {
            enabled: true,
            session_ttl_s: 60,
            max_links: 16,
            max_links_per_session: 4,
        }
    }
}

/// Parses `[modules.NAME]` into `T`, naming the key and the reason on failure.
fn section<T: serde::de::DeserializeOwned>(config: &Config, name: &str) -> anyhow::Result<T> {
    let value = config.module(name);
    serde_path_to_error::deserialize(value)
        .map_err(|e| anyhow::anyhow!("[modules.{name}] {}: {}", e.path(), e.inner()))
}

/// The browser link, ready to be mounted into the HTTP app and started as modules.
#[derive(Debug, Clone)]
pub struct BrowserLink {
    shared: Arc<Shared>,
}

impl BrowserLink {
    /// Reads `[modules.browser]`; `fft_hop` is the spectra's hop (`[modules.audio_fft]`) and `voice` the engine
    /// that speaks the agent's language (`[modules.tts]`), which the page is told in its welcome; `shutdown` turning
    /// true closes every page socket.
    pub fn from_config(
        config: &Config,
        fft_hop: usize,
        voice: &'static str,
        shutdown: watch::Receiver<bool>,
    ) -> anyhow::Result<Self> {
        let browser: BrowserConfig = section(config, "browser")?;
        if browser.session_ttl_s == 0 {
            anyhow::bail!("[modules.browser] session_ttl_s: must be at least 1");
        }
        if browser.max_links == 0 || browser.max_links_per_session == 0 {
            anyhow::bail!("[modules.browser] max_links, max_links_per_session: must be at least 1");
        }
        let limits = SessionLimits {
            unused_ttl: Duration::from_secs(browser.session_ttl_s),
            ..SessionLimits::default()
        };
        Ok(BrowserLink {
            shared: Arc::new(Shared {
                client: OnceLock::new(),
                playback: OnceLock::new(),
                links: Arc::new(Mutex::new(LinkBoard::new(
                    browser.max_links,
                    browser.max_links_per_session,
                ))),
                sessions: Mutex::new(SessionStore::new(limits)),
                session_ttl_s: browser.session_ttl_s,
                roles: Mutex::new(RoleBoard::default()),
                pages: Mutex::new(HashMap::new()),
                next_page: AtomicU64::new(1),
                fft_hop,
                language: config.agent.language.clone(),
                voice,
                shutdown,
            }),
        })
    }

    /// Routes: `/` and the page's assets, `POST /api/session`, `GET /link` (the WebSocket).
    pub fn router(&self) -> axum::Router {
        routes::router(self.shared.clone())
    }

    /// Gives the link its hub connection (the `browser` module does this; tests and tools may do it themselves).
    /// Returns false if it already has one.
    pub fn attach(&self, client: flow::Client) -> bool {
        self.shared.client.set(client).is_ok()
    }

    /// The module to start: `browser`, which gives the link its hub connection (`enabled = false` in
    /// `[modules.browser]` turns it off).
    pub fn module(&self) -> Box<dyn Module> {
        Box::new(LinkModule {
            shared: self.shared.clone(),
        })
    }
}

/// The `browser` module: gives the link its hub connection and holds it until shutdown.
struct LinkModule {
    shared: Arc<Shared>,
}

impl Module for LinkModule {
    fn name(&self) -> &'static str {
        "browser"
    }

    fn run(self: Box<Self>, mut ctx: ModuleContext) -> ModuleFuture {
        Box::pin(async move {
            if self.shared.client.set(ctx.client.clone()).is_err() {
                // Someone attached a client by hand; two would fight over the media channels.
                anyhow::bail!("the browser module was started twice");
            }
            let playback = ctx
                .client
                .publisher(
                    agent_contract::channels::PLAYBACK.name,
                    agent_contract::channels::headers::PLAYBACK,
                )
                .await?;
            // Set once: this module runs once (checked above).
            let _ = self.shared.playback.set(playback);
            ctx.stopped().await;
            Ok(())
        })
    }
}
