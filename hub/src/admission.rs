//! The cap on connections that have not logged in yet (`hub.max_unauthenticated`): each takes a place on
//! accept and gives it back on login or close, so a flood of strangers cannot hold the hub's memory.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The count of connections that have not logged in yet, against a cap.
#[derive(Debug)]
pub struct Admission {
    waiting: AtomicUsize,
    cap: usize,
}

impl Admission {
    pub fn new(cap: usize) -> Self {
        Admission {
            waiting: AtomicUsize::new(0),
            cap,
        }
    }

    /// Admits one more unauthenticated connection, or refuses it when the cap
    /// is reached.
    pub fn admit(self: &Arc<Self>) -> Option<Stranger> {
        let admitted = self
            .waiting
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < self.cap).then_some(n + 1)
            })
            .is_ok();
        admitted.then(|| Stranger(Some(self.clone())))
    }

    /// Connections waiting to log in now.
    pub fn waiting(&self) -> usize {
        self.waiting.load(Ordering::Acquire)
    }
}

/// One place among the unauthenticated connections, given back on login or close.
#[derive(Debug)]
pub struct Stranger(Option<Arc<Admission>>);

impl Stranger {
    /// No place taken: the server's own modules are never capped.
    pub fn trusted() -> Self {
        Stranger(None)
    }

    /// The connection logged in: its place is free for another stranger.
    pub fn logged_in(&mut self) {
        if let Some(a) = self.0.take() {
            a.waiting.fetch_sub(1, Ordering::AcqRel);
        }
    }
}

impl Drop for Stranger {
    fn drop(&mut self) {
        self.logged_in();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn places_are_given_back_on_login_and_on_drop() {
        let a = Arc::new(Admission::new(2));
        let mut one = a.admit().expect("first");
        let two = a.admit().expect("second");
        assert!(a.admit().is_none(), "the cap holds");
        one.logged_in();
        assert_eq!(a.waiting(), 1);
        one.logged_in();
        assert_eq!(a.waiting(), 1, "a place is given back once");
        drop(two);
        assert_eq!(a.waiting(), 0);
        assert!(a.admit().is_some());
    }
}
