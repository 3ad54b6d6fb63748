//! How many page sockets are open, in total and per credential, against the caps of `[modules.browser]`: each
//! socket costs a hub subscription set and ~150 kB of buffers, so a credential (or a script holding one) must not
//! open hundreds.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};

/// Why a socket was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LinkRefused {
    #[error(
        "too many pages open: {0} in total (modules.browser.max_links); close a tab or raise the cap"
    )]
    Total(usize),
    #[error(
        "too many pages open in this browser: {0} (modules.browser.max_links_per_session); close a tab or raise the cap"
    )]
    PerCredential(usize),
}

/// Open sockets by credential key.
#[derive(Debug)]
pub struct LinkBoard {
    max_total: usize,
    max_per_credential: usize,
    open: HashMap<String, usize>,
    total: usize,
}

impl LinkBoard {
    pub fn new(max_total: usize, max_per_credential: usize) -> Self {
        LinkBoard {
            max_total,
            max_per_credential,
            open: HashMap::new(),
            total: 0,
        }
    }

    /// Whether one more socket under `credential` would be accepted now.
    pub fn check(&self, credential: &str) -> Result<(), LinkRefused> {
        if self.total >= self.max_total {
            return Err(LinkRefused::Total(self.max_total));
        }
        if self.open.get(credential).copied().unwrap_or(0) >= self.max_per_credential {
            return Err(LinkRefused::PerCredential(self.max_per_credential));
        }
        Ok(())
    }

    /// Counts one more socket under `credential`, if the caps allow it.
    pub fn open(&mut self, credential: &str) -> Result<(), LinkRefused> {
        self.check(credential)?;
        *self.open.entry(credential.to_string()).or_insert(0) += 1;
        self.total += 1;
        Ok(())
    }

    /// A socket under `credential` closed.
    pub fn close(&mut self, credential: &str) {
        if let Some(n) = self.open.get_mut(credential) {
            *n -= 1;
            self.total -= 1;
            if *n == 0 {
                self.open.remove(credential);
            }
        }
    }
}

/// One open socket's place on the board, given back when dropped.
#[derive(Debug)]
pub struct LinkSlot {
    board: Arc<Mutex<LinkBoard>>,
    credential: String,
}

impl LinkSlot {
    /// Takes a place under `credential`, if the caps allow it.
    pub fn take(board: &Arc<Mutex<LinkBoard>>, credential: &str) -> Result<LinkSlot, LinkRefused> {
        lock(board).open(credential)?;
        Ok(LinkSlot {
            board: board.clone(),
            credential: credential.to_string(),
        })
    }
}

impl Drop for LinkSlot {
    fn drop(&mut self) {
        lock(&self.board).close(&self.credential);
    }
}

fn lock(board: &Mutex<LinkBoard>) -> std::sync::MutexGuard<'_, LinkBoard> {
    // Counts stay consistent across a panic elsewhere: each change is one statement.
    board.lock().unwrap_or_else(PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn caps_hold_per_credential_and_in_total_and_free_up_on_close() {
        let mut b = LinkBoard::new(3, 2);
        assert_eq!(b.open("a"), Ok(()));
        assert_eq!(b.open("a"), Ok(()));
        assert_eq!(b.open("a"), Err(LinkRefused::PerCredential(2)));
        assert_eq!(b.open("b"), Ok(()));
        assert_eq!(b.check("c"), Err(LinkRefused::Total(3)));
        b.close("a");
        assert_eq!(b.open("c"), Ok(()));
        b.close("b");
        b.close("c");
        b.close("a");
        b.close("never-opened");
        assert_eq!(b.total, 0);
        assert!(b.open.is_empty());
    }

    #[test]
    fn a_dropped_slot_gives_its_place_back() {
        let board = Arc::new(Mutex::new(LinkBoard::new(1, 1)));
        let slot = LinkSlot::take(&board, "a").expect("first");
        assert_eq!(
            LinkSlot::take(&board, "b").map(drop),
            Err(LinkRefused::Total(1))
        );
        drop(slot);
        assert!(LinkSlot::take(&board, "b").is_ok());
    }
}
