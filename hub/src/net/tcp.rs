//! FlowProtocol over TCP: the accept loop.

use std::sync::Arc;

use flow::transport::tcp::TcpTransport;
use tokio::net::TcpListener;
use tokio::task::JoinSet;
use tracing::warn;

use super::serve_connection;
use crate::shared::Shared;

/// Accepts connections until shutdown, then waits for them to close.
pub async fn accept_loop(listener: TcpListener, shared: Arc<Shared>) {
    let mut shutdown = shared.shutdown.subscribe();
    let mut connections = JoinSet::new();
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => {
                    connections.spawn(serve_connection(TcpTransport::from_stream(stream), shared.clone(), false));
                }
                // Typically out of file descriptors: back off instead of spinning.
                Err(e) => {
                    warn!("tcp accept failed: {e}");
                    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                }
            },
            Some(_) = connections.join_next() => {}
            _ = shutdown.changed() => break,
        }
    }
    // Each connection sees the shutdown too and flushes its goodbye within its own grace period.
    while connections.join_next().await.is_some() {}
}
