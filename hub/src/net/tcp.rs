//! FlowProtocol over TCP: the accept loop. Each connection takes its place among the strangers (by its address) at
//! accept; a process out of descriptors backs off (`descriptors.rs`).

use std::sync::Arc;

use flow::transport::tcp::TcpTransport;
use tokio::net::TcpListener;
use tokio::task::JoinSet;

use super::descriptors::AcceptFailures;
use super::serve_connection;
use crate::admission::Origin;
use crate::shared::Shared;

/// Accepts connections until shutdown, then waits for them to close.
pub async fn accept_loop(listener: TcpListener, shared: Arc<Shared>) {
    let mut shutdown = shared.shutdown.subscribe();
    let mut connections = JoinSet::new();
    let mut failures = AcceptFailures::new("flow tcp");
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, addr)) => {
                    failures.succeeded();
                    let stranger = shared.admission.admit(Origin::ip(addr.ip()));
                    connections.spawn(serve_connection(
                        TcpTransport::from_stream(stream),
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
    // Each connection sees the shutdown too and flushes its goodbye within its own grace period.
    while connections.join_next().await.is_some() {}
}
