//! The replayer: republishes a recording's messages on the hub with their recorded timing.
//!
//! Timing is drift-free: each message has an absolute deadline, the replay's start plus its log time's distance
//! from the first message's (divided by the speed), on the monotonic clock; a late message never delays the ones
//! after it. How late each message was handed to the hub is reported (p50, p99, max).

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use bytes::Bytes;
use flow::{Client, ErrorCode, FlowError, Publisher};
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::encoding;
use crate::error::RecordError;
use crate::lateness::{Lateness, LatenessSummary};
use crate::reader::{Entry, RecordedChannel, RecordingReader};
use crate::select::{Remap, Selection};
use crate::sink::META_HEADER;

/// How a recording is replayed.
#[derive(Debug, Clone)]
pub struct ReplayOptions {
    /// 2.0 replays twice as fast.
    pub speed: f64,
    /// Start again at the end, until stopped.
    pub looping: bool,
    /// Recorded channel names to replay (before remapping).
    pub channels: Selection,
    pub remap: Remap,
    /// Before the first message, wait until every replayed channel has a subscriber.
    pub wait_subscribers: bool,
    /// Time between creating the channels and the first message, so that subscribers that wait for a channel by
    /// name (sticky subscriptions) are subscribed when it starts.
    pub lead_in: Duration,
}

impl Default for ReplayOptions {
    fn default() -> Self {
        ReplayOptions {
            speed: 1.0,
            looping: false,
            channels: Selection::default(),
            remap: Remap::default(),
            wait_subscribers: false,
            lead_in: Duration::from_millis(500),
        }
    }
}

/// What a replay did.
#[derive(Debug, Clone, Default)]
pub struct ReplayReport {
    /// Messages published, per hub channel (after remapping).
    pub published: BTreeMap<String, u64>,
    /// Channels not replayed, with the reason (another owner already has the name).
    pub skipped: Vec<(String, String)>,
    /// Recorded messages that did not decode into a payload.
    pub undecodable: u64,
    pub lateness: LatenessSummary,
    /// Passes through the file that were started.
    pub passes: u64,
    /// Where the file is cut, if it is.
    pub truncated: Option<String>,
}

/// Replays recordings through one client.
#[derive(Debug)]
pub struct Replayer {
    client: Client,
    opts: ReplayOptions,
}

/// The replayed channels of a recording and its time span.
struct Plan {
    /// Per MCAP channel id: which publisher, and how to decode.
    routes: BTreeMap<u16, Route>,
    /// Per publisher: the hub name and the recorded header.
    outputs: Vec<(String, String)>,
    first_ns: u64,
    last_ns: u64,
    messages: u64,
    truncated: Option<String>,
}

#[derive(Clone)]
struct Route {
    output: usize,
    encoding: String,
    schema: Option<String>,
}

/// A decoded message on its way from the reader thread.
struct Due {
    output: usize,
    payload: Bytes,
    /// Nanoseconds after the replay's start, at speed 1.
    offset_ns: u64,
}

impl Replayer {
    pub fn new(client: Client, opts: ReplayOptions) -> Replayer {
        Replayer { client, opts }
    }

    /// Replays `path` until its end (or, looping, until `stop` completes).
    pub async fn run(
        &self,
        path: &Path,
        stop: impl std::future::Future<Output = ()>,
    ) -> Result<ReplayReport, RecordError> {
        let plan = {
            let path = path.to_path_buf();
            let opts = self.opts.clone();
            tokio::task::spawn_blocking(move || plan(&path, &opts))
                .await
                .map_err(|e| RecordError::Writer(e.to_string()))??
        };
        let mut report = ReplayReport {
            truncated: plan.truncated.clone(),
            ..ReplayReport::default()
        };
        let mut publishers: Vec<Option<Publisher>> = Vec::new();
        for (name, header) in &plan.outputs {
            match self.client.publisher(name, header).await {
                Ok(p) => publishers.push(Some(p)),
                Err(FlowError::Hub(e)) if e.code == ErrorCode::Exists => {
                    report
                        .skipped
                        .push((name.clone(), "exists with another owner".into()));
                    publishers.push(None);
                }
                Err(e) => return Err(e.into()),
            }
        }
        if plan.messages == 0 {
            return Ok(report);
        }
        if self.opts.wait_subscribers {
            for p in publishers.iter().flatten() {
                let mut subs = p.subscribers();
                subs.wait_for(|on| *on)
                    .await
                    .map_err(|_| RecordError::Flow(FlowError::Closed))?;
            }
        }
        tokio::time::sleep(self.opts.lead_in).await;

        let (tx, mut rx) = mpsc::channel::<Due>(256);
        let reader = {
            let file = path.to_path_buf();
            let routes = plan.routes.clone();
            let looping = self.opts.looping;
            let (first, span) = (plan.first_ns, loop_span(&plan));
            std::thread::Builder::new()
                .name("mcap-replay-reader".into())
                .spawn(move || feed(&file, &routes, first, span, looping, &tx))
                .map_err(|e| RecordError::file(path, e))?
        };
        let speed = if self.opts.speed > 0.0 {
            self.opts.speed
        } else {
            1.0
        };
        let start = Instant::now();
        let mut lateness = Lateness::default();
        tokio::pin!(stop);
        loop {
            let due = tokio::select! {
                due = rx.recv() => match due { Some(due) => due, None => break },
                () = &mut stop => break,
            };
            let deadline = start + Duration::from_nanos((due.offset_ns as f64 / speed) as u64);
            tokio::select! {
                () = tokio::time::sleep_until(deadline.checked_sub(EARLY).unwrap_or(deadline)) => {}
                () = &mut stop => break,
            }
            finish_wait(deadline);
            lateness.record(Instant::now().saturating_duration_since(deadline));
            if let Some(Some(publisher)) = publishers.get(due.output) {
                publisher.publish(due.payload).await?;
                *report
                    .published
                    .entry(publisher.name().to_string())
                    .or_default() += 1;
            }
        }
        drop(rx);
        let fed = tokio::task::spawn_blocking(move || reader.join())
            .await
            .map_err(|e| RecordError::Writer(e.to_string()))?
            .map_err(|_| RecordError::Writer("the replay reader panicked".into()))?;
        let (passes, undecodable) = fed?;
        // Everything published before the ping's answer has reached the hub.
        self.client.ping().await?;
        report.passes = passes;
        report.undecodable = undecodable;
        report.lateness = lateness.summary();
        Ok(report)
    }
}

/// How long before a deadline the runtime's timer hands over to the thread. Tokio's timer has millisecond
/// granularity (a sleep ends at the first tick after its deadline, up to a millisecond late, more on a busy
/// machine); the rest of the wait is a plain thread sleep, exact to tens of microseconds.
const EARLY: Duration = Duration::from_millis(2);

/// Waits on the thread for the last moments before `deadline`: at most [`EARLY`] of blocking per message, which
/// the replay's task can afford (the SDK's writer sends the previous message during the timer sleep before it).
fn finish_wait(deadline: Instant) {
    let left = deadline.saturating_duration_since(Instant::now());
    if !left.is_zero() {
        std::thread::sleep(left);
    }
}

/// The time from one pass's first message to the next pass's: the recording's span plus one mean gap, so that
/// the last message of a pass and the first of the next do not fall on the same instant.
fn loop_span(plan: &Plan) -> u64 {
    let span = plan.last_ns.saturating_sub(plan.first_ns);
    span + span / plan.messages.saturating_sub(1).max(1)
}

/// Reads the file once for its channels and time span.
fn plan(path: &Path, opts: &ReplayOptions) -> Result<Plan, RecordError> {
    let mut routes = BTreeMap::new();
    let mut outputs: Vec<(String, String)> = Vec::new();
    let (mut first_ns, mut last_ns, mut messages) = (u64::MAX, 0, 0);
    let mut reader = RecordingReader::open(path)?;
    while let Some(entry) = reader.next_entry()? {
        match entry {
            Entry::Channel(c) => {
                if let Some(route) = route(&c, opts, &mut outputs) {
                    routes.insert(c.id, route);
                }
            }
            Entry::Message(m) if routes.contains_key(&m.channel) => {
                first_ns = first_ns.min(m.log_ns);
                last_ns = last_ns.max(m.log_ns);
                messages += 1;
            }
            Entry::Message(_) => {}
        }
    }
    Ok(Plan {
        routes,
        outputs,
        first_ns: if messages == 0 { 0 } else { first_ns },
        last_ns,
        messages,
        truncated: reader.truncated().map(str::to_string),
    })
}

/// Where a recorded channel goes: nowhere for derived topics (no hub header) and unselected channels.
fn route(
    c: &RecordedChannel,
    opts: &ReplayOptions,
    outputs: &mut Vec<(String, String)>,
) -> Option<Route> {
    let header = c.metadata.get(META_HEADER)?;
    if !opts.channels.matches(&c.topic) {
        return None;
    }
    let name = opts.remap.apply(&c.topic).to_string();
    // Several MCAP channels may carry one hub channel (a header change, raw fallbacks): one publisher, with the
    // first header recorded.
    let output = match outputs.iter().position(|(n, _)| *n == name) {
        Some(i) => i,
        None => {
            outputs.push((name, header.clone()));
            outputs.len() - 1
        }
    };
    Some(Route {
        output,
        encoding: c.message_encoding.clone(),
        schema: c.schema.clone(),
    })
}

/// The reader thread: decodes messages in file order and hands them over with their offsets, pass after pass
/// when looping, until the replay stops listening. Returns the passes started and the undecodable messages.
fn feed(
    path: &Path,
    routes: &BTreeMap<u16, Route>,
    first_ns: u64,
    span_ns: u64,
    looping: bool,
    tx: &mpsc::Sender<Due>,
) -> Result<(u64, u64), RecordError> {
    let (mut passes, mut undecodable) = (0u64, 0u64);
    loop {
        let base = passes.saturating_mul(span_ns);
        passes += 1;
        let mut reader = RecordingReader::open(path)?;
        while let Some(entry) = reader.next_entry()? {
            let Entry::Message(m) = entry else { continue };
            let Some(route) = routes.get(&m.channel) else {
                continue;
            };
            let Ok(payload) = encoding::decode(&route.encoding, route.schema.as_deref(), &m.data)
            else {
                undecodable += 1;
                continue;
            };
            let due = Due {
                output: route.output,
                payload: Bytes::from(payload),
                offset_ns: base + m.log_ns.saturating_sub(first_ns),
            };
            if tx.blocking_send(due).is_err() {
                return Ok((passes, undecodable));
            }
        }
        if !looping {
            return Ok((passes, undecodable));
        }
    }
}
