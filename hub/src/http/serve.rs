//! Serves the HTTP edge's connections: HTTP/1.1 through hyper, over TLS when `[http] tls` asks for it, with the
//! bounds `axum::serve` lacks. A connection must send its headers within `http.header_timeout_ms` and is closed when
//! idle as long; at most `http.max_connections` are served at once; and one that has shown no credential holds a
//! place among the strangers (`admission.rs`), so that idle connections can neither exhaust the descriptors nor
//! keep a client with a credential out. The access gate marks a connection known ([`HttpConn::known`]); `/flow`
//! takes its place over to FlowProtocol's login.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use axum::Router;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::TcpListener;
use tokio::task::JoinSet;
use tower::Service;

use super::access::PeerInfo;
use super::connection::HttpConn;
use super::tls::Tls;
use crate::admission::{Origin, Stranger};
use crate::net::descriptors::AcceptFailures;
use crate::shared::Shared;

/// How long connections get to finish their requests once the server stops.
const STOP_GRACE: Duration = Duration::from_secs(2);

/// One of the `http.max_connections` places, given back on close.
struct Place(Arc<AtomicUsize>);

impl Drop for Place {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

/// Accepts and serves connections until shutdown, then lets them finish within a grace period.
pub async fn run(listener: TcpListener, tls: Option<Tls>, router: Router, shared: Arc<Shared>) {
    let mut shutdown = shared.shutdown.subscribe();
    let mut connections = JoinSet::new();
    let open = Arc::new(AtomicUsize::new(0));
    let mut failures = AcceptFailures::new("http");
    let local = listener.local_addr().ok();
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, remote)) => {
                    failures.succeeded();
                    let origin = Origin::ip(remote.ip());
                    let cap = shared.config.http.max_connections;
                    if open.fetch_add(1, Ordering::AcqRel) >= cap {
                        open.fetch_sub(1, Ordering::AcqRel);
                        shared.admission.notices().note(&origin, "http-cap", || {
                            format!("http connection from {remote} closed at accept: {cap} are open (http.max_connections)")
                        });
                        continue;
                    }
                    let place = Place(open.clone());
                    let _ = stream.set_nodelay(true);
                    let info = PeerInfo { remote, local: stream.local_addr().ok().or(local) };
                    let stranger = shared.admission.admit(origin);
                    connections.spawn(serve_one(
                        stream, info, stranger, place, tls.clone(), router.clone(), shared.clone(),
                    ));
                }
                Err(e) => failures.failed(&e, || async { drop(listener.accept().await) }).await,
            },
            Some(_) = connections.join_next() => {}
            _ = async { drop(shutdown.wait_for(|down| *down).await) } => break,
        }
    }
    // Each connection sees the shutdown too and closes once its current request is answered.
    let drained = async { while connections.join_next().await.is_some() {} };
    if tokio::time::timeout(STOP_GRACE, drained).await.is_err() {
        connections.abort_all();
    }
}

/// One connection: the TLS handshake if any, then HTTP/1.1 until it closes, is evicted or the server stops.
async fn serve_one(
    stream: tokio::net::TcpStream,
    info: PeerInfo,
    stranger: Stranger,
    place: Place,
    tls: Option<Tls>,
    router: Router,
    shared: Arc<Shared>,
) {
    let _place = place;
    let header_timeout = Duration::from_millis(shared.config.http.header_timeout_ms);
    let eviction = stranger.watch();
    let conn = HttpConn::new(stranger);
    match tls {
        None => http(stream, info, conn, eviction, router, shared).await,
        Some(tls) => {
            let handshake = tokio::time::timeout(header_timeout, tls.acceptor.accept(stream));
            let stream = tokio::select! {
                done = handshake => match done {
                    Ok(Ok(s)) => s,
                    Ok(Err(e)) => {
                        tracing::debug!(peer = %info.remote, "tls handshake failed: {e}");
                        return;
                    }
                    Err(_) => {
                        tracing::debug!(peer = %info.remote, "tls handshake not done within http.header_timeout_ms");
                        return;
                    }
                },
                _ = eviction.evicted() => return,
            };
            http(stream, info, conn, eviction, router, shared).await;
        }
    }
}

async fn http<I>(
    io: I,
    info: PeerInfo,
    conn: HttpConn,
    eviction: crate::admission::EvictionWatch,
    router: Router,
    shared: Arc<Shared>,
) where
    I: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let mut shutdown = shared.shutdown.subscribe();
    let header_timeout = Duration::from_millis(shared.config.http.header_timeout_ms);
    let handle = conn.clone();
    let service = hyper::service::service_fn(move |mut req: hyper::Request<Incoming>| {
        req.extensions_mut().insert(ConnectInfo(info));
        req.extensions_mut().insert(handle.clone());
        let mut router = router.clone();
        async move { router.call(req.map(axum::body::Body::new)).await }
    });
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(header_timeout);
    let serving = builder
        .serve_connection(TokioIo::new(io), service)
        .with_upgrades();
    tokio::pin!(serving);
    let ended = tokio::select! {
        ended = serving.as_mut() => ended,
        why = eviction.evicted() => {
            // Only a connection that never showed a credential is in the table.
            drop(conn);
            let _ = why;
            return;
        }
        _ = async { drop(shutdown.wait_for(|down| *down).await) } => {
            serving.as_mut().graceful_shutdown();
            serving.await
        }
    };
    if let Err(e) = ended {
        log_end(&e, info.remote);
    }
}

fn log_end(e: &hyper::Error, peer: SocketAddr) {
    if e.is_timeout() {
        tracing::debug!(%peer, "http connection closed: headers not sent within http.header_timeout_ms, or idle");
    } else {
        tracing::debug!(%peer, "http connection ended: {e}");
    }
}
