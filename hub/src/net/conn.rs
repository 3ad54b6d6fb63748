//! Drives one connection over any transport: a reader loop that decodes
//! commands into the session, and a writer loop that drains the outbox.
//!
//! Before login a connection is a stranger: it may send only a small frame,
//! must log in within the login timeout, and holds a place in the table of
//! strangers, which may evict it to make room (see `crate::admission`). After
//! login a frame, once begun, must be finished within `hub.frame_timeout_ms`.

use std::sync::Arc;
use std::time::Duration;

use tokio::time::Instant;

use flow::connection::{ConnError, Connection, FrameWriter};
use flow::protocol::decode_command;
use flow::transport::{Transport, TransportWrite};
use tracing::{debug, info, warn};

use crate::admission::Stranger;
use crate::hub::{Outbox, ShmPeer};
use crate::net::shm_writer::ShmWriter;
use crate::session::{Outcome, Session, SessionContext};
use crate::shared::Shared;

/// Payload bytes taken from the outbox per write.
const WRITE_BATCH: usize = 512 * 1024;
/// Commands handled in a row before the reader lets other tasks run: half a
/// subscriber lane's default 64 messages, so the writers that a flood of
/// publishes wakes get to drain their lanes before they overflow. Each yield
/// costs a trip through the scheduler, so not after every command.
const FAIR_SHARE: usize = 32;
/// How long a closing connection may take to flush what is queued.
const FLUSH_GRACE: Duration = Duration::from_secs(2);
/// The largest frame a connection may send before it has logged in. A login
/// (version, a 40-character token, a name) takes well under 1 kB; a stranger
/// must not make the hub reserve megabytes for a frame it will never finish.
pub const PRE_LOGIN_MAX_FRAME: usize = 16 * 1024;
/// The login deadline of a stranger that came while its table was filling up: a real client logs in within a
/// round trip, and a flood's places turn over faster.
pub const PRESSED_LOGIN: Duration = Duration::from_secs(1);

/// Why a connection ended: a normal close is logged at info, a misbehaving
/// client at warn as `killing spurious client`.
#[derive(Debug)]
enum End {
    /// The peer left, the server shut down, or the hub closed the outbox for a
    /// reason of its own (logged as given).
    Closed(String),
    /// The client broke the protocol or a limit.
    Spurious(String),
    /// A stranger out of time: logged once per address per interval, as a flood makes many.
    Stranger(String),
    /// A stranger evicted to make room (the table logs evictions, once per address per interval).
    Evicted(String),
}

/// How the writer task ended.
#[derive(Debug)]
enum WriterEnd {
    /// The outbox was closed and everything queued went out.
    Drained,
    Failed(String),
}

/// Serves one connection until it closes, misbehaves or the server shuts down.
/// `internal` connections are the server's own modules: trusted, never capped
/// (their `stranger` is [`Stranger::trusted`]); any other comes with its place
/// among the strangers, taken at accept.
pub async fn serve_connection<T: Transport>(
    transport: T,
    shared: Arc<Shared>,
    internal: bool,
    mut stranger: Stranger,
) {
    let mut shutdown = shared.shutdown.subscribe();
    // Shared memory is offered only where a segment's descriptor can be handed over: the Unix socket.
    let segments = shared.hub.segments();
    let shm_peer = (transport.passes_fds() && segments.settings().enabled).then(|| {
        Arc::new(ShmPeer::new(
            segments.settings().held,
            segments.shared_stats(),
        ))
    });
    let shm_writer = shm_peer
        .clone()
        .map(|peer| ShmWriter::new(peer, segments.clone()));
    let Connection {
        peer,
        mut reader,
        writer,
    } = Connection::new(transport, PRE_LOGIN_MAX_FRAME);
    let (conn, outbox) = shared.hub.connect(&peer);
    debug!(%peer, conn, "connection opened");
    let mut writer_task = tokio::spawn(write_loop(writer, outbox.clone(), shm_writer));
    // Set once the writer task has finished and been awaited: a finished
    // JoinHandle must not be polled again.
    let mut writer_done = false;
    let context = SessionContext {
        hub: shared.hub.clone(),
        pairdb: shared.pairdb.clone(),
        tokens: shared.tokens.clone(),
    };
    let mut session = Session::new(conn, peer.clone(), outbox.clone(), context, internal);
    session.set_shm_peer(shm_peer.clone());
    let login_within = stranger.login_deadline(
        Duration::from_millis(shared.config.hub.login_timeout_ms),
        PRESSED_LOGIN,
    );
    let login_deadline = tokio::time::sleep(login_within);
    tokio::pin!(login_deadline);
    let frame_timeout = Duration::from_millis(shared.config.hub.frame_timeout_ms);
    // When the last whole frame came: a frame begun and left unfinished for `frame_timeout` after it ends the
    // connection (checked when the timer fires, as a begun frame is not visible while a read is pending).
    let mut last_frame = Instant::now();
    let mut since_yield = 0usize;
    let end: End = 'serve: loop {
        let awaiting_login = !session.is_logged_in();
        let read = tokio::select! {
            frame = reader.read_frame() => frame,
            why = stranger.evicted(), if awaiting_login => break End::Evicted(why.to_string()),
            _ = tokio::time::sleep_until(last_frame + frame_timeout), if !awaiting_login => {
                if reader.partial() > 0 {
                    break End::Spurious(format!(
                        "a frame begun has not been finished within {} ms ({} bytes of it came; hub.frame_timeout_ms)",
                        frame_timeout.as_millis(), reader.partial()
                    ));
                }
                last_frame = Instant::now();
                continue;
            }
            _ = outbox.wait_closed() => {
                let reason = outbox.closed().unwrap_or_default();
                break if outbox.overflowed() { End::Spurious(reason) } else { End::Closed(reason) };
            }
            _ = shutdown.changed() => break End::Closed("server shutting down".into()),
            _ = &mut login_deadline, if awaiting_login => break End::Stranger(format!(
                "no login within {} ms (hub.login_timeout_ms{})", login_within.as_millis(),
                if login_within < Duration::from_millis(shared.config.hub.login_timeout_ms) {
                    ", shortened while many connections wait to log in"
                } else { "" }
            )),
            ended = &mut writer_task => {
                writer_done = true;
                break match ended {
                    Ok(WriterEnd::Failed(e)) => End::Closed(format!("write failed: {e}")),
                    Ok(WriterEnd::Drained) => End::Closed(outbox.closed().unwrap_or_default()),
                    Err(e) => End::Spurious(format!("writer task failed: {e}")),
                };
            }
        };
        last_frame = Instant::now();
        let mut next = match read {
            Ok(Some(raw)) => Some(raw),
            Ok(None) => break End::Closed("closed by the peer".into()),
            // A transport's protocol violation (text on the WebSocket link) is the client's fault.
            Err(ConnError::Io(e)) if e.kind() == std::io::ErrorKind::InvalidData => {
                break End::Spurious(e.to_string());
            }
            Err(e @ ConnError::Io(_)) => break End::Closed(e.to_string()),
            Err(e) => break End::Spurious(e.to_string()),
        };
        // Frames that came with the same read are handled here, without
        // setting up the select above again for each one.
        while let Some(raw) = next {
            let env = match decode_command(raw) {
                Ok(env) => env,
                Err(e) => break 'serve End::Spurious(format!("undecodable command: {e}")),
            };
            let was_logged_in = session.is_logged_in();
            if let Outcome::Close(reason) = session.handle(env).await {
                break 'serve End::Spurious(reason);
            }
            if !was_logged_in && session.is_logged_in() {
                // Known now: full-size frames, no deadline, no place among strangers.
                reader.set_max_frame(shared.config.hub.max_frame);
                stranger.logged_in();
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
                Err(e) => break 'serve End::Spurious(ConnError::Frame(e).to_string()),
            };
        }
    };
    let origin = stranger.origin();
    drop(stranger);
    let reason = match end {
        End::Evicted(reason) => {
            debug!(%peer, conn, "connection closed: {reason}");
            reason
        }
        End::Stranger(reason) => {
            shared.admission.notices().note(&origin, "login", || {
                format!("killing spurious client {peer}: {reason}")
            });
            reason
        }
        End::Spurious(reason) => {
            warn!(%peer, conn, "killing spurious client: {reason}");
            reason
        }
        End::Closed(reason) => {
            info!(%peer, conn, "connection closed: {reason}");
            reason
        }
    };
    shared.hub.disconnect(conn);
    outbox.close(reason);
    // Every slot this connection held goes back (and wakes its writer if it waited for one).
    if let Some(peer) = &shm_peer {
        peer.clear();
    }
    // Let the writer send what is queued (e.g. the refusal of a bad login).
    if !writer_done
        && tokio::time::timeout(FLUSH_GRACE, &mut writer_task)
            .await
            .is_err()
    {
        writer_task.abort();
    }
}

async fn write_loop<W: TransportWrite>(
    mut writer: FrameWriter<W>,
    outbox: Arc<Outbox>,
    mut shm: Option<ShmWriter>,
) -> WriterEnd {
    let mut batch = Vec::new();
    loop {
        if let Some(shm) = &shm
            && outbox.is_drained()
            && let Err(e) = shm.idle()
        {
            outbox.close(e.to_string());
            return WriterEnd::Failed(e.to_string());
        }
        outbox.ready().await;
        if let Some(shm) = &shm {
            shm.busy();
        }
        outbox.pop_batch(&mut batch, WRITE_BATCH);
        if batch.is_empty() {
            if outbox.closed().is_some() {
                break;
            }
            continue;
        }
        let mut queued = Ok(());
        for event in batch.drain(..) {
            match &mut shm {
                Some(shm) if queued.is_ok() => queued = shm.queue(&mut writer, event).await,
                Some(_) => {}
                None => writer.queue_event(&event),
            }
        }
        if let Err(e) = queued.and(writer.flush().await) {
            debug!("write failed: {e}");
            outbox.close(format!("write failed: {e}"));
            return WriterEnd::Failed(e.to_string());
        }
    }
    let _ = writer.shutdown().await;
    WriterEnd::Drained
}
