//! FlowProtocol over UDP (`server.flow_udp`): one socket, and a demultiplexer that gives each session its own
//! connection (`flow::transport::udp`), served like any accepted one: a stranger until it logs in, with the
//! pre-login limits of TCP.
//!
//! Only a hello (at least 1200 bytes, so that the 16-byte answer amplifies nothing) makes a session; its answer
//! carries a random session id. Every other datagram must name a live session and come from that session's
//! address, or it is dropped and counted, never answered: garbage and spoofed datagrams cost a decode each and
//! nothing else. Sessions are at most [`MAX_SESSIONS`]; those not logged in are held by the table of strangers
//! (`admission.rs`), which evicts the oldest of a crowded address, so a flood of hellos turns over a bounded set.
//! The demultiplexer puts each datagram straight into its session's engine and wakes the session's waiting half
//! (`flow::transport::udp::Inbox`): no queue and no task between the socket and the connection. A session whose
//! reader has fallen `DELIVERED_BACKLOG` frames behind has further datagrams dropped (and counted), which the
//! sender's retransmission covers for reliable data.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering;

use flow::transport::udp::batch::{BatchSocket, Received};
use flow::transport::udp::datagram::{Datagram, Kind};
use flow::transport::udp::{Inbox, UdpStats, UdpTransport};
use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeMetric};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use rand::Rng;
use tokio::sync::mpsc;
use tokio::task::JoinSet;
use tracing::debug;

use super::serve_connection;
use crate::admission::Origin;
use crate::shared::Shared;

/// Sessions open at once, logged in or not; a hello beyond it is dropped.
pub const MAX_SESSIONS: usize = 4096;

/// A live session as the demultiplexer knows it.
#[derive(Debug)]
struct Entry {
    addr: SocketAddr,
    nonce: u32,
    inbox: Inbox,
}

/// The sessions, by id and by address (one session per client socket).
#[derive(Debug, Default)]
struct Sessions {
    by_id: HashMap<u32, Entry>,
    by_addr: HashMap<SocketAddr, u32>,
}

impl Sessions {
    /// Forgets session `id` and ends it (a session replaced from the same address no longer hears anything).
    fn remove(&mut self, id: u32) {
        if let Some(e) = self.by_id.remove(&id) {
            e.inbox.end();
            if self.by_addr.get(&e.addr) == Some(&id) {
                self.by_addr.remove(&e.addr);
            }
        }
    }
}

/// Serves the UDP edge until shutdown, then routes datagrams until every session has said goodbye.
pub async fn serve(socket: BatchSocket, shared: Arc<Shared>) {
    let socket = Arc::new(socket);
    let stats = Arc::new(UdpStats::default());
    shared.metrics.register_collector(Box::new(UdpCollector {
        stats: stats.clone(),
    }));
    let mut shutdown = shared.shutdown.subscribe();
    let mut stopping = false;
    let mut sessions = Sessions::default();
    let mut connections = JoinSet::new();
    let (ended_tx, mut ended_rx) = mpsc::unbounded_channel::<u32>();
    let mut received = Received::default();
    loop {
        if stopping && connections.is_empty() {
            break;
        }
        tokio::select! {
            got = socket.recv(&mut received) => match got {
                // A receive holds several datagrams (a picture's fragments coalesced by the kernel, `batch.rs`).
                Ok(()) => {
                    received.count(&stats.received, &stats.receive_calls);
                    for (from, bytes) in received.datagrams() {
                        let Ok(d) = Datagram::decode(bytes) else {
                            UdpStats::add(&stats.malformed, 1);
                            continue;
                        };
                        if d.kind == Kind::Hello {
                            if !stopping {
                                hello(&d, bytes.len(), from, &socket, &shared, &stats, &mut sessions, &mut connections, &ended_tx).await;
                            }
                            continue;
                        }
                        match sessions.by_id.get(&d.session) {
                            Some(e) if e.addr == from && d.kind != Kind::HelloAck => e.inbox.push(bytes),
                            _ => UdpStats::add(&stats.spoofed, 1),
                        }
                    }
                }
                // An ICMP error for an earlier send (a client gone); the socket itself is fine.
                Err(e) => debug!("flow udp: {e}"),
            },
            Some(id) = ended_rx.recv() => {
                sessions.remove(id);
                stats.sessions.store(sessions.by_id.len() as u64, Ordering::Relaxed);
            }
            Some(_) = connections.join_next() => {}
            _ = shutdown.changed(), if !stopping => stopping = true,
        }
    }
}

/// Answers a hello: the same answer again for a hello sent again, a new session otherwise.
#[allow(clippy::too_many_arguments)]
async fn hello(
    d: &Datagram<'_>,
    len: usize,
    from: SocketAddr,
    socket: &Arc<BatchSocket>,
    shared: &Arc<Shared>,
    stats: &Arc<UdpStats>,
    sessions: &mut Sessions,
    connections: &mut JoinSet<()>,
    ended: &mpsc::UnboundedSender<u32>,
) {
    let nonce = d.session;
    if let Some(&id) = sessions.by_addr.get(&from) {
        if sessions.by_id.get(&id).is_some_and(|e| e.nonce == nonce) {
            // Our answer was lost: the same session again.
            let _ = socket
                .socket()
                .send_to(&Datagram::bare(Kind::HelloAck, id, nonce).to_vec(), from)
                .await;
            return;
        }
        // A new session from the same socket replaces the old one, whose queue closes.
        sessions.remove(id);
    }
    if sessions.by_id.len() >= MAX_SESSIONS {
        UdpStats::add(&stats.dropped, 1);
        return;
    }
    let id = loop {
        let id: u32 = rand::rng().random();
        if id != 0 && !sessions.by_id.contains_key(&id) {
            break id;
        }
    };
    let ack = Datagram::bare(Kind::HelloAck, id, nonce).to_vec();
    let transport = UdpTransport::accepted(
        socket.clone(),
        from,
        id,
        len.saturating_sub(ack.len()),
        stats.clone(),
    );
    sessions.by_id.insert(
        id,
        Entry {
            addr: from,
            nonce,
            inbox: transport.inbox(),
        },
    );
    sessions.by_addr.insert(from, id);
    stats
        .sessions
        .store(sessions.by_id.len() as u64, Ordering::Relaxed);
    let stranger = shared.admission.admit(Origin::ip(from.ip()));
    let shared = shared.clone();
    let ended = ended.clone();
    connections.spawn(async move {
        serve_connection(transport, shared, false, stranger).await;
        let _ = ended.send(id);
    });
    let _ = socket.socket().send_to(&ack, from).await;
}

/// The edge's counters, read at each scrape.
#[derive(Debug)]
struct UdpCollector {
    stats: Arc<UdpStats>,
}

impl Collector for UdpCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        let s = &self.stats;
        for (name, help, counter) in [
            (
                "flow_udp_malformed_datagrams",
                "UDP datagrams that did not decode, dropped unanswered",
                &s.malformed,
            ),
            (
                "flow_udp_spoofed_datagrams",
                "UDP datagrams for no session or from another address than the session's, dropped unanswered",
                &s.spoofed,
            ),
            (
                "flow_udp_dropped_datagrams",
                "UDP datagrams dropped for want of room (a full session queue or window, the session cap)",
                &s.dropped,
            ),
            (
                "flow_udp_lost_messages",
                "Best-effort messages (publishes) received over UDP with a fragment missing, dropped whole",
                &s.lost,
            ),
            (
                "flow_udp_retransmitted_datagrams",
                "Reliable UDP datagrams, and best-effort fragments asked for, that the hub sent again",
                &s.retransmitted,
            ),
            (
                "flow_udp_nacks",
                "Requests the hub sent for missing fragments of best-effort UDP messages",
                &s.nacks,
            ),
            (
                "flow_udp_duplicate_datagrams",
                "Duplicate UDP datagrams discarded",
                &s.duplicates,
            ),
            (
                "flow_udp_sent_datagrams",
                "UDP datagrams the hub's sessions sent, retransmissions included",
                &s.sent,
            ),
            (
                "flow_udp_send_calls",
                "System calls that sent them: a message's fragments go out in one segmented send, other bursts in one sendmmsg",
                &s.send_calls,
            ),
            (
                "flow_udp_received_datagrams",
                "UDP datagrams the hub's edge received",
                &s.received,
            ),
            (
                "flow_udp_receive_calls",
                "System calls that received them: recvmmsg, with the kernel coalescing a segmented send into one buffer",
                &s.receive_calls,
            ),
        ] {
            ConstCounter::new(UdpStats::get(counter)).encode(encoder.encode_descriptor(
                name,
                help,
                None,
                ConstCounter::new(0u64).metric_type(),
            )?)?;
        }
        let sessions = i64::try_from(UdpStats::get(&s.sessions)).unwrap_or(i64::MAX);
        ConstGauge::new(sessions).encode(encoder.encode_descriptor(
            "flow_udp_sessions",
            "UDP sessions open now, logged in or not",
            None,
            ConstGauge::new(0i64).metric_type(),
        )?)?;
        Ok(())
    }
}
