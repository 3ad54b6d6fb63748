//! FlowProtocol over a Unix domain socket: binding and the accept loop.

use std::path::Path;
use std::sync::Arc;

use super::descriptors::AcceptFailures;
use super::serve_connection;
use crate::admission::Origin;
use crate::shared::Shared;
use flow::transport::unix::UnixTransport;
use tokio::net::UnixListener;
use tokio::task::JoinSet;

/// Binds `path`, replacing a stale socket file left by a killed server.
pub fn bind(path: &Path) -> std::io::Result<UnixListener> {
    if path.exists() {
        // Only a socket nobody answers on is stale; a live one means another server runs.
        if std::os::unix::net::UnixStream::connect(path).is_ok() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::AddrInUse,
                format!("{} is in use by a running server", path.display()),
            ));
        }
        std::fs::remove_file(path)?;
    }
    UnixListener::bind(path)
}

/// Accepts connections until shutdown, removes the socket file, then waits for the connections to close.
pub async fn accept_loop(listener: UnixListener, path: std::path::PathBuf, shared: Arc<Shared>) {
    let mut shutdown = shared.shutdown.subscribe();
    let mut connections = JoinSet::new();
    let mut next = 0u64;
    let mut failures = AcceptFailures::new("flow unix");
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => {
                    failures.succeeded();
                    next += 1;
                    let peer = format!("unix:{next}");
                    let stranger = shared.admission.admit(Origin::unix());
                    connections.spawn(serve_connection(
                        UnixTransport::from_stream(stream, peer),
                        shared.clone(),
                        false,
                        stranger,
                    ));
                }
                Err(e) => failures.failed(&e, || async { drop(listener.accept().await) }).await,
            },
            Some(_) = connections.join_next() => {}
            _ = shutdown.changed() => break,
        }
    }
    let _ = std::fs::remove_file(path);
    while connections.join_next().await.is_some() {}
}
