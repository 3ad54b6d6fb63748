//! FlowProtocol on the serial lines the hub serves (`[[hub.serial]]`): each line is one connection, opened at
//! start and opened again, with back-off, whenever it fails, closes or is unplugged, until shutdown.
//!
//! A line has no accept: the satellite at its other end is simply there or not. So a line is served like any
//! connection that just came in (a stranger until it logs in, held to the login deadline), and when that
//! connection ends, for whatever reason, the line is opened afresh for the next login. A board that reboots
//! mid-session therefore gets a clean session once its login is refused or times out.

use std::sync::Arc;
use std::time::Duration;

use flow::transport::serial::{LineStats, SerialTransport};
use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeLabelSet, EncodeMetric};
use prometheus_client::metrics::counter::ConstCounter;
use tracing::{debug, info, warn};

use super::serve_connection;
use crate::admission::Origin;
use crate::config::SerialLine;
use crate::shared::Shared;

/// The first wait before opening a line again; it doubles after each failed open up to [`BACKOFF_MAX`].
const BACKOFF_MIN: Duration = Duration::from_millis(100);
const BACKOFF_MAX: Duration = Duration::from_secs(5);

/// Serves every configured line until shutdown; their counters go to `/metrics`.
pub async fn serve_lines(shared: Arc<Shared>) {
    let lines: Vec<(SerialLine, Arc<LineStats>)> = shared
        .config
        .hub
        .serial
        .iter()
        .map(|l| (l.clone(), Arc::default()))
        .collect();
    if lines.is_empty() {
        return;
    }
    shared.metrics.register_collector(Box::new(LineCollector {
        lines: lines
            .iter()
            .map(|(l, s)| (l.path.display().to_string(), s.clone()))
            .collect(),
    }));
    let mut tasks = tokio::task::JoinSet::new();
    for (line, stats) in lines {
        tasks.spawn(serve_line(line, stats, shared.clone()));
    }
    while tasks.join_next().await.is_some() {}
}

/// Opens `line`, serves it until its connection ends, and again, until shutdown.
async fn serve_line(line: SerialLine, stats: Arc<LineStats>, shared: Arc<Shared>) {
    let mut shutdown = shared.shutdown.subscribe();
    let path = line.path.display().to_string();
    let mut backoff = BACKOFF_MIN;
    let mut failing = false;
    loop {
        if *shutdown.borrow() {
            return;
        }
        match SerialTransport::open(&line.path, line.baud) {
            Ok(transport) => {
                if failing {
                    info!(line = %path, baud = line.baud, "serial line is back");
                } else {
                    debug!(line = %path, baud = line.baud, "serial line open");
                }
                failing = false;
                backoff = BACKOFF_MIN;
                let stranger = shared.admission.admit(Origin::unix());
                serve_connection(
                    transport.with_stats(stats.clone()),
                    shared.clone(),
                    false,
                    stranger,
                )
                .await;
                debug!(line = %path, damaged = stats.damaged(), "serial connection ended; opening the line again");
            }
            Err(e) => {
                // Said once per outage: a line that stays unplugged retries quietly.
                if !failing {
                    warn!(line = %path, "cannot open serial line: {e}; retrying every {}s at most", BACKOFF_MAX.as_secs());
                }
                failing = true;
            }
        }
        tokio::select! {
            () = tokio::time::sleep(if failing { backoff } else { BACKOFF_MIN }) => {}
            _ = shutdown.changed() => return,
        }
        if failing {
            backoff = (backoff * 2).min(BACKOFF_MAX);
        }
    }
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct LineLabel {
    line: String,
}

/// The lines' counters, read at each scrape.
#[derive(Debug)]
struct LineCollector {
    lines: Vec<(String, Arc<LineStats>)>,
}

impl Collector for LineCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        for (name, help, value) in [
            (
                "flow_serial_packets",
                "Intact packets read from a serial line",
                LineStats::packets as fn(&LineStats) -> u64,
            ),
            (
                "flow_serial_damaged_packets",
                "Packets read from a serial line and dropped as damaged (checksum, stuffing, length)",
                LineStats::damaged,
            ),
        ] {
            let mut family = encoder.encode_descriptor(
                name,
                help,
                None,
                ConstCounter::new(0u64).metric_type(),
            )?;
            for (line, stats) in &self.lines {
                ConstCounter::new(value(stats))
                    .encode(family.encode_family(&LineLabel { line: line.clone() })?)?;
            }
        }
        Ok(())
    }
}
