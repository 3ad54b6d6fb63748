//! The browser link's shared state: what the HTTP handlers and every page's socket task read and change. A leaf,
//! so that the handlers (`routes.rs`, `socket.rs`) and the file that builds it (`mod.rs`) share it without a cycle.

use std::collections::HashMap;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

use tokio::sync::{mpsc, watch};

use super::links::LinkBoard;
use super::role::{PageId, RoleBoard};
use super::session::SessionStore;

/// What one page's socket task is told by others.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Notice {
    /// The holder left and this page, next in line, now holds the role.
    Granted,
}

/// State shared by the HTTP handlers and every page's socket task.
#[derive(Debug)]
pub struct Shared {
    /// The link's hub connection, set when the `browser` module starts.
    pub client: OnceLock<flow::Client>,
    /// `Agent.playback`, where the holder's page says when each utterance of speech began to be heard; made by the
    /// `browser` module when it starts, so the channel is there before any page plays.
    pub playback: OnceLock<flow::Publisher>,
    pub links: Arc<Mutex<LinkBoard>>,
    pub sessions: Mutex<SessionStore>,
    pub session_ttl_s: u64,
    pub roles: Mutex<RoleBoard>,
    pub pages: Mutex<HashMap<PageId, mpsc::Sender<Notice>>>,
    pub next_page: AtomicU64,
    pub fft_hop: usize,
    /// The agent's language (`agent.language`), told to the page in its welcome.
    pub language: String,
    /// The engine that speaks it (`piper` or `espeak`), told to the page in its welcome too.
    pub voice: &'static str,
    pub shutdown: watch::Receiver<bool>,
}

pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic while holding one of these locks leaves plain data behind (no invariants span a panic), so the
    // poisoned state is still usable.
    m.lock().unwrap_or_else(|p| p.into_inner())
}
