//! Drives one connection over any transport: a reader loop that decodes
//! commands into the session, and a writer loop that drains the outbox.

use std::sync::Arc;
use std::time::Duration;

use flow::connection::{Connection, FrameWriter};
use flow::protocol::decode_command;
use flow::transport::{Transport, TransportWrite};
use tracing::{debug, info, warn};

use crate::hub::Outbox;
use crate::server::Shared;
use crate::session::{Outcome, Session};

/// Payload bytes taken from the outbox per write.
const WRITE_BATCH: usize = 512 * 1024;
/// Commands handled in a row before the reader yields to other tasks.
const BURST: u32 = 16;
/// How long a closing connection may take to flush what is queued.
const FLUSH_GRACE: Duration = Duration::from_secs(2);

/// Serves one connection until it closes, misbehaves or the server shuts down.
pub async fn serve_connection<T: Transport>(transport: T, shared: Arc<Shared>, internal: bool) {
    let mut shutdown = shared.shutdown.subscribe();
    let Connection {
        peer,
        mut reader,
        writer,
    } = Connection::new(transport, shared.config.hub.max_frame);
    let (conn, outbox) = shared.hub.connect(&peer);
    debug!(%peer, conn, "connection opened");
    let mut writer_task = tokio::spawn(write_loop(writer, outbox.clone()));
    let mut session = Session::new(conn, peer.clone(), outbox.clone(), shared.clone(), internal);
    let mut handled = 0u32;
    let reason: Option<String> = loop {
        tokio::select! {
            frame = reader.read_frame() => match frame {
                Ok(Some(raw)) => match decode_command(raw) {
                    Ok(env) => match session.handle(env).await {
                        Outcome::Continue => {
                            // A burst already buffered would otherwise be handled without
                            // a pause, filling subscribers' lanes faster than their writers
                            // can run; let them drain now and then.
                            handled = handled.wrapping_add(1);
                            if handled % BURST == 0 {
                                tokio::task::yield_now().await;
                            }
                        }
                        Outcome::Close(reason) => break Some(reason),
                    },
                    Err(e) => break Some(format!("undecodable command: {e}")),
                },
                Ok(None) => break None,
                Err(e) => break Some(e.to_string()),
            },
            _ = outbox.wait_closed() => break outbox.closed(),
            _ = shutdown.changed() => break None,
            _ = &mut writer_task => break Some("write failed".into()),
        }
    };
    if let Some(reason) = &reason {
        warn!(%peer, conn, "killing spurious client: {reason}");
    } else {
        info!(%peer, conn, "connection closed");
    }
    shared.hub.disconnect(conn);
    outbox.close(reason.unwrap_or_else(|| "closed".into()));
    // Let the writer send what is queued (e.g. the refusal of a bad login).
    if tokio::time::timeout(FLUSH_GRACE, &mut writer_task)
        .await
        .is_err()
    {
        writer_task.abort();
    }
}

async fn write_loop<W: TransportWrite>(mut writer: FrameWriter<W>, outbox: Arc<Outbox>) {
    let mut batch = Vec::new();
    loop {
        outbox.ready().await;
        outbox.pop_batch(&mut batch, WRITE_BATCH);
        if batch.is_empty() {
            if outbox.closed().is_some() {
                break;
            }
            continue;
        }
        for event in batch.drain(..) {
            writer.queue_event(&event);
        }
        if let Err(e) = writer.flush().await {
            debug!("write failed: {e}");
            outbox.close(format!("write failed: {e}"));
            return;
        }
    }
    let _ = writer.shutdown().await;
}
