//! FlowProtocol over TCP: the accept loop.

use std::sync::Arc;

use flow::transport::tcp::TcpTransport;
use tokio::net::TcpListener;
use tracing::warn;

use super::serve_connection;
use crate::server::Shared;

/// Accepts connections until shutdown.
pub async fn accept_loop(listener: TcpListener, shared: Arc<Shared>) {
    let mut shutdown = shared.shutdown.subscribe();
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => {
                    tokio::spawn(serve_connection(TcpTransport::from_stream(stream), shared.clone(), false));
                }
                // Typically out of file descriptors: back off instead of spinning.
                Err(e) => {
                    warn!("tcp accept failed: {e}");
                    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                }
            },
            _ = shutdown.changed() => return,
        }
    }
}
