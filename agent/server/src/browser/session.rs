//! Session tokens the server issues to its own page; a WebSocket is accepted only with one of them.
//!
//! A token is a random 128-bit value in hex. It must be used within `unused_ttl` of being issued, is bound to at
//! most one open socket at a time, and stays valid for `idle_ttl` after its socket closes so the same tab can
//! reconnect. The store is bounded: issuing past `capacity` forgets the oldest unbound token.

use std::collections::HashMap;
use std::time::{Duration, Instant};

/// How long tokens live and how many may exist.
#[derive(Debug, Clone, Copy)]
pub struct SessionLimits {
    pub unused_ttl: Duration,
    pub idle_ttl: Duration,
    pub capacity: usize,
}

impl Default for SessionLimits {
    fn default() -> Self {
        SessionLimits {
            unused_ttl: Duration::from_secs(60),
            idle_ttl: Duration::from_secs(600),
            capacity: 64,
        }
    }
}

/// Why a token was not accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SessionError {
    #[error("unknown or expired session")]
    Unknown,
    #[error("session is already connected")]
    InUse,
}

#[derive(Debug)]
struct Entry {
    bound: bool,
    /// Whether a socket has ever used it (such tokens get the longer reconnect lifetime).
    used: bool,
    /// Issue time for a never-used token, else when its last socket closed.
    since: Instant,
}

/// The server's tokens; callers keep it behind a mutex.
#[derive(Debug)]
pub struct SessionStore {
    limits: SessionLimits,
    entries: HashMap<String, Entry>,
}

impl SessionStore {
    pub fn new(limits: SessionLimits) -> Self {
        SessionStore {
            limits,
            entries: HashMap::new(),
        }
    }

    /// Issues a fresh token.
    pub fn issue(&mut self, now: Instant) -> String {
        self.expire(now);
        while self.entries.len() >= self.limits.capacity.max(1) {
            let oldest = self
                .entries
                .iter()
                .filter(|(_, e)| !e.bound)
                .min_by_key(|(_, e)| e.since);
            match oldest.map(|(k, _)| k.clone()) {
                Some(k) => {
                    self.entries.remove(&k);
                }
                // Every token has a live socket: the page count is the limit, not the store.
                None => break,
            }
        }
        let token = format!("{:032x}", rand::random::<u128>());
        self.entries.insert(
            token.clone(),
            Entry {
                bound: false,
                used: false,
                since: now,
            },
        );
        token
    }

    /// Binds `token` to a new socket.
    pub fn bind(&mut self, token: &str, now: Instant) -> Result<(), SessionError> {
        self.expire(now);
        let entry = self.entries.get_mut(token).ok_or(SessionError::Unknown)?;
        if entry.bound {
            return Err(SessionError::InUse);
        }
        entry.bound = true;
        entry.used = true;
        Ok(())
    }

    /// The socket bound to `token` closed; the token may reconnect for a while.
    pub fn unbind(&mut self, token: &str, now: Instant) {
        if let Some(e) = self.entries.get_mut(token) {
            e.bound = false;
            e.since = now;
        }
    }

    fn expire(&mut self, now: Instant) {
        let limits = self.limits;
        self.entries.retain(|_, e| {
            let ttl = if e.used {
                limits.idle_ttl
            } else {
                limits.unused_ttl
            };
            e.bound || now.duration_since(e.since) < ttl
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> SessionLimits {
        SessionLimits {
            unused_ttl: Duration::from_secs(60),
            idle_ttl: Duration::from_secs(600),
            capacity: 3,
        }
    }

    #[test]
    fn a_token_binds_once_at_a_time() {
        let t0 = Instant::now();
        let mut s = SessionStore::new(limits());
        let tok = s.issue(t0);
        assert_eq!(tok.len(), 32);
        assert_eq!(s.bind("nope", t0), Err(SessionError::Unknown));
        assert_eq!(s.bind(&tok, t0), Ok(()));
        assert_eq!(s.bind(&tok, t0), Err(SessionError::InUse));
        s.unbind(&tok, t0);
        assert_eq!(s.bind(&tok, t0 + Duration::from_secs(5)), Ok(()));
    }

    #[test]
    fn unused_tokens_expire() {
        let t0 = Instant::now();
        let mut s = SessionStore::new(limits());
        let tok = s.issue(t0);
        assert_eq!(
            s.bind(&tok, t0 + Duration::from_secs(61)),
            Err(SessionError::Unknown)
        );
    }

    #[test]
    fn capacity_forgets_the_oldest_unbound_token() {
        let t0 = Instant::now();
        let mut s = SessionStore::new(limits());
        let a = s.issue(t0);
        let b = s.issue(t0 + Duration::from_millis(1));
        s.bind(&a, t0).expect("bind a");
        let _c = s.issue(t0 + Duration::from_millis(2));
        let _d = s.issue(t0 + Duration::from_millis(3));
        assert_eq!(
            s.bind(&b, t0),
            Err(SessionError::Unknown),
            "b was the oldest unbound"
        );
        s.unbind(&a, t0);
        assert_eq!(s.bind(&a, t0), Ok(()), "a bound token is never evicted");
    }
}
