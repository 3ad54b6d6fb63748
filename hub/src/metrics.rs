//! `GET /metrics`: the hub's and the modules' figures in the Prometheus text format (0.0.4), through the
//! `prometheus-client` crate. The hub's own counters (channels, connections, service calls) are read from the hub
//! at scrape time by [`HubCollector`]; histograms that need every event (tick lateness here, vision, ASR and
//! conversation stages in the agent's observer module) are families registered once and observed as events happen.

use std::sync::{Arc, Mutex, PoisonError};

use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeLabelSet, EncodeMetric};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::{Metric, Registry};

use crate::hub::Hub;

/// A histogram family whose members all have the same buckets.
pub type HistogramFamily<L> = Family<L, Histogram, fn() -> Histogram>;

/// Buckets for latencies from 50 µs to about 26 s (doubling), which covers a tick's lateness as well as a long
/// utterance's transcription.
pub fn latency_histogram() -> Histogram {
    Histogram::new(exponential_buckets(0.000_05, 2.0, 20))
}

/// A new histogram family with [`latency_histogram`] buckets.
pub fn latency_family<L>() -> HistogramFamily<L>
where
    L: Clone + std::hash::Hash + Eq,
{
    Family::new_with_constructor(latency_histogram as fn() -> Histogram)
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct PulseLabel {
    pub pulse: &'static str,
}

/// The registry behind `/metrics`, shared by the hub and the modules.
#[derive(Debug)]
pub struct Metrics {
    registry: Mutex<Registry>,
    /// How late each pulse fired against its schedule.
    pub tick_lateness: HistogramFamily<PulseLabel>,
}

impl Metrics {
    pub fn new(hub: Arc<Hub>) -> Self {
        let mut registry = Registry::default();
        let tick_lateness = latency_family();
        registry.register(
            "flow_tick_lateness_seconds",
            "How late FastTick, SlowTick and OneSecTick fired against their schedule",
            tick_lateness.clone(),
        );
        registry.register_collector(Box::new(HubCollector { hub }));
        Metrics {
            registry: Mutex::new(registry),
            tick_lateness,
        }
    }

    /// Adds a module's metric (a family it keeps a clone of and updates).
    pub fn register(&self, name: &str, help: &str, metric: impl Metric) {
        self.lock().register(name, help, metric);
    }

    /// Adds figures read at each scrape (the serial lines' counters).
    pub fn register_collector(&self, collector: Box<dyn Collector>) {
        self.lock().register_collector(collector);
    }

    /// Everything, in the Prometheus text exposition format.
    pub fn render(&self) -> Result<String, std::fmt::Error> {
        let mut out = String::new();
        prometheus_client::encoding::prometheus_text::encode(&mut out, &self.lock())?;
        Ok(out)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Registry> {
        self.registry.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct ChannelLabels {
    channel: String,
    kind: &'static str,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct TransportLabel {
    transport: String,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct ViaLabel {
    via: &'static str,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct CallLabels {
    service: String,
    outcome: &'static str,
}

/// Reads the hub's counters at each scrape: nothing is counted twice, and an idle hub does no metric work.
#[derive(Debug)]
struct HubCollector {
    hub: Arc<Hub>,
}

/// One counter family with a member per channel, its value read off the channel's stats.
fn channel_counters(
    encoder: &mut DescriptorEncoder,
    name: &str,
    help: &str,
    channels: &[flow::ChannelInfo],
    value: impl Fn(&flow::ChannelInfo) -> u64,
) -> Result<(), std::fmt::Error> {
    let mut family =
        encoder.encode_descriptor(name, help, None, ConstCounter::new(0u64).metric_type())?;
    for c in channels {
        ConstCounter::new(value(c)).encode(family.encode_family(&channel_labels(c))?)?;
    }
    Ok(())
}

fn channel_labels(c: &flow::ChannelInfo) -> ChannelLabels {
    ChannelLabels {
        channel: c.name.clone(),
        kind: match c.kind {
            flow::ChannelKind::Stream => "stream",
            flow::ChannelKind::Service => "service",
        },
    }
}

impl Collector for HubCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        let channels = self.hub.list_channels();
        channel_counters(
            &mut encoder,
            "flow_channel_messages",
            "Messages published on a channel since it was created",
            &channels,
            |c| c.stats.msgs,
        )?;
        channel_counters(
            &mut encoder,
            "flow_channel_bytes",
            "Payload bytes published on a channel since it was created",
            &channels,
            |c| c.stats.bytes,
        )?;
        channel_counters(
            &mut encoder,
            "flow_channel_dropped",
            "Messages of a channel dropped for subscribers that fell behind (drop-oldest)",
            &channels,
            |c| c.stats.dropped,
        )?;
        {
            let mut family = encoder.encode_descriptor(
                "flow_channel_subscribers",
                "Subscribers of a channel now",
                None,
                ConstGauge::new(0i64).metric_type(),
            )?;
            for c in &channels {
                ConstGauge::new(i64::from(c.stats.subscribers))
                    .encode(family.encode_family(&channel_labels(c))?)?;
            }
        }
        {
            let mut family = encoder.encode_descriptor(
                "flow_connections",
                "Open connections by transport (tcp, unix, ws, module)",
                None,
                ConstGauge::new(0i64).metric_type(),
            )?;
            for (transport, n) in self.hub.connections_by_transport() {
                let n = i64::try_from(n).unwrap_or(i64::MAX);
                ConstGauge::new(n).encode(family.encode_family(&TransportLabel { transport })?)?;
            }
        }
        let segments = self.hub.segments();
        let shm = segments.stats();
        ConstGauge::new(shm.segments()).encode(encoder.encode_descriptor(
            "flow_shm_segments",
            "Shared-memory segments alive now (a channel's, or a removed channel's whose slots are still held)",
            None,
            ConstGauge::new(0i64).metric_type(),
        )?)?;
        ConstGauge::new(shm.slots_held()).encode(encoder.encode_descriptor(
            "flow_shm_slots_held",
            "Shared-memory slots whose message a queue, a subscriber or the recorder holds now",
            None,
            ConstGauge::new(0i64).metric_type(),
        )?)?;
        ConstCounter::new(shm.messages()).encode(encoder.encode_descriptor(
            "flow_shm_messages",
            "Messages published by reference through shared memory",
            None,
            ConstCounter::new(0u64).metric_type(),
        )?)?;
        ConstCounter::new(shm.inline()).encode(encoder.encode_descriptor(
            "flow_shm_inline",
            "Deliveries of such messages as bytes to a shared-memory subscriber that held all the slots it may \
             (hub.shm_held)",
            None,
            ConstCounter::new(0u64).metric_type(),
        )?)?;
        {
            let mut family = encoder.encode_descriptor(
                "flow_shm_released",
                "Slots subscribers gave back, by way: a Release frame (frame) or the release ring, with no frame \
                 (ring)",
                None,
                ConstCounter::new(0u64).metric_type(),
            )?;
            ConstCounter::new(shm.released_by_frame())
                .encode(family.encode_family(&ViaLabel { via: "frame" })?)?;
            ConstCounter::new(shm.released_by_ring())
                .encode(family.encode_family(&ViaLabel { via: "ring" })?)?;
        }
        {
            let mut family = encoder.encode_descriptor(
                "flow_service_calls",
                "Service calls by outcome: answered, failed (the service answered an error), timeout, gone \
                 (the owner left) or overloaded",
                None,
                ConstCounter::new(0u64).metric_type(),
            )?;
            for (service, counts) in self.hub.service_calls() {
                for (outcome, n) in counts.by_outcome() {
                    let labels = CallLabels {
                        service: service.clone(),
                        outcome,
                    };
                    ConstCounter::new(n).encode(family.encode_family(&labels)?)?;
                }
            }
        }
        Ok(())
    }
}
