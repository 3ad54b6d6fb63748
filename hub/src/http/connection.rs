//! The HTTP connection a request came on, as the request's extension: while it has shown no credential it holds a
//! stranger's place (`admission.rs`). The serve loop makes it (`serve.rs`), the access gate marks it known
//! (`access.rs`), `/flow` takes its place over (`mod.rs`); a leaf, so that none of them imports another for it.

use std::sync::{Arc, Mutex, PoisonError};

use crate::admission::Stranger;

/// The HTTP connection a request came on, as the request's extension: while it has shown no credential it holds
/// a stranger's place.
#[derive(Debug, Clone)]
pub struct HttpConn(Arc<Mutex<Option<Stranger>>>);

impl HttpConn {
    /// A connection that holds `stranger`'s place until it shows a credential.
    pub fn new(stranger: Stranger) -> Self {
        HttpConn(Arc::new(Mutex::new(Some(stranger))))
    }

    /// A request on it showed a credential: it no longer counts among the strangers.
    pub fn known(&self) {
        if let Some(mut s) = self.take_stranger() {
            s.logged_in();
        }
    }

    /// Hands its stranger's place over (to a `/flow` link, which keeps it until FlowProtocol's login).
    pub fn take_stranger(&self) -> Option<Stranger> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner).take()
    }
}
