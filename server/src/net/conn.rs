//! Drives one connection over any transport: a reader loop that decodes
//! commands into the session, and a writer loop that drains the outbox.

use std::sync::Arc;
use std::time::Duration;

use flow::connection::{ConnError, Connection, FrameWriter};
use flow::protocol::decode_command;
use flow::transport::{Transport, TransportWrite};
use tracing::{debug, info, warn};

use crate::hub::Outbox;
use crate::server::Shared;
use crate::session::{Outcome, Session};

/// Payload bytes taken from the outbox per write.
const WRITE_BATCH: usize = 512 * 1024;
/// Commands handled in a row before the reader lets other tasks run: half a
/// subscriber lane's default 64 messages, so the writers that a flood of
/// publishes wakes get to drain their lanes before they overflow. Each yield
/// costs a trip through the scheduler, so not after every command.
const FAIR_SHARE: usize = 32;
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
    let mut since_yield = 0usize;
    let reason: Option<String> = 'serve: loop {
        let read = tokio::select! {
            frame = reader.read_frame() => frame,
            _ = outbox.wait_closed() => break outbox.closed(),
            _ = shutdown.changed() => break None,
            _ = &mut writer_task => break Some("write failed".into()),
        };
        let mut next = match read {
            Ok(Some(raw)) => Some(raw),
            Ok(None) => break None,
            Err(e) => break Some(e.to_string()),
        };
        // Frames that came with the same read are handled here, without
        // setting up the select above again for each one.
        while let Some(raw) = next {
            let env = match decode_command(raw) {
                Ok(env) => env,
                Err(e) => break 'serve Some(format!("undecodable command: {e}")),
            };
            if let Outcome::Close(reason) = session.handle(env).await {
                break 'serve Some(reason);
            }
            since_yield += 1;
            if since_yield == FAIR_SHARE {
                // A publisher that never pauses would otherwise keep this
                // worker until its budget ran out, while the writers it woke
                // wait and their lanes overflow.
                since_yield = 0;
                tokio::task::yield_now().await;
            }
            next = match reader.parse_buffered() {
                Ok(frame) => frame,
                Err(e) => break 'serve Some(ConnError::Frame(e).to_string()),
            };
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
