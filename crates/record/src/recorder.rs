//! The recorder: subscribes to every stream channel a [`Selection`] matches, now and as they appear, and hands
//! their messages to the MCAP writer thread.
//!
//! Loss policy: nothing here waits for the hub. Each subscription is the SDK's drop-oldest queue; when the file
//! falls behind, the writer's bounded queue fills, this side stops taking messages, and the subscription queues
//! drop their oldest (counted per channel as `dropped`); the hub in turn drops for a recorder that reads too
//! slowly. Every loss shows as a gap in a channel's sequence numbers (`missing` in the report).
//!
//! Log time: the MCAP log time of a message is the hub's receive time, `Data::ts_us` (the hub stamps every
//! message as its publish arrives); FlowProtocol carries no clock of the publisher's, so the publish time is the
//! same stamp.

use std::collections::BTreeMap;
use std::path::Path;
use std::pin::Pin;
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use flow::{ChannelInfo, ChannelKind, Client, ClientEvent, Data, Subscription};
use futures_util::stream::{SelectAll, Stream, StreamExt};
use tokio::sync::{broadcast, mpsc, oneshot};

use crate::error::RecordError;
use crate::select::Selection;
use crate::sink::{self, ChannelTally, Item, SinkOptions, SinkReport};

/// How a recording is made.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    pub channels: Selection,
    pub sink: SinkOptions,
    /// How often the current chunk is closed even if it is not full: the most a `kill -9` loses.
    pub flush_every: Duration,
    /// Messages the writer thread may have queued before the subscriptions start dropping.
    pub writer_queue: usize,
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            channels: Selection::default(),
            sink: SinkOptions::default(),
            flush_every: Duration::from_secs(1),
            writer_queue: 256,
        }
    }
}

/// What a recording holds and lost, per channel.
#[derive(Debug, Clone, Default)]
pub struct RecordReport {
    pub channels: BTreeMap<String, ChannelReport>,
    /// Messages written on the detections' annotation topic.
    pub annotations: u64,
}

/// One channel of a [`RecordReport`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ChannelReport {
    pub written: ChannelTally,
    /// Messages the recorder's subscription queue dropped (part of `written.missing`).
    pub dropped: u64,
}

impl RecordReport {
    pub fn messages(&self) -> u64 {
        self.channels.values().map(|c| c.written.messages).sum()
    }
}

/// A recording in progress; [`Recorder::stop`] ends it and writes the file's summary.
#[derive(Debug)]
pub struct Recorder {
    stop: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<Result<RecordReport, RecordError>>,
    /// Closed when the recording has ended by itself (a failed write): see [`Recorder::ended`].
    ended: tokio::sync::watch::Receiver<()>,
}

type Messages = Pin<Box<dyn Stream<Item = (String, Data)> + Send>>;

impl Recorder {
    /// Creates `path` and starts recording what `client` (an asynchronous client, so that it sees new channels)
    /// can subscribe to.
    pub async fn start(
        client: Client,
        path: &Path,
        opts: RecordOptions,
    ) -> Result<Recorder, RecordError> {
        let (items, writer) = sink::spawn(path, &opts.sink, opts.writer_queue)?;
        // Events first, so that a channel created between the listing and the subscription is not missed.
        let events = client.events();
        let existing = client.channels().await?;
        let (stop, stopped) = oneshot::channel();
        let (ending, ended) = tokio::sync::watch::channel(());
        let task = tokio::spawn(async move {
            // Dropped when this task ends, which wakes `Recorder::ended`.
            let _ending = ending;
            let mut run = Run {
                client,
                opts,
                items,
                subs: BTreeMap::new(),
                last_seq: BTreeMap::new(),
                streams: SelectAll::new(),
            };
            let looped = run.run(existing, events, stopped).await;
            let dropped: BTreeMap<String, u64> = run
                .subs
                .iter()
                .map(|(name, sub)| (name.clone(), sub.dropped()))
                .collect();
            // Dropping the sender ends the writer thread, which writes the summary.
            drop(run);
            let written = tokio::task::spawn_blocking(move || writer.join())
                .await
                .map_err(|e| RecordError::Writer(e.to_string()))?
                .map_err(|_| RecordError::Writer("the writer thread panicked".into()))?;
            // A failed write is the cause of a failed hand-over, so it is the error to report.
            let written = written?;
            looped?;
            Ok(report(written, &dropped))
        });
        Ok(Recorder {
            stop: Some(stop),
            task,
            ended,
        })
    }

    /// Resolves once the recording has ended without being stopped: a write failed (the disk is full). Then
    /// [`Recorder::stop`] returns the error at once.
    pub async fn ended(&mut self) {
        while self.ended.changed().await.is_ok() {}
    }

    /// Stops recording, finishes the file and says what it holds.
    pub async fn stop(mut self) -> Result<RecordReport, RecordError> {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        (&mut self.task)
            .await
            .map_err(|e| RecordError::Writer(e.to_string()))?
    }
}

/// The longest a stop waits for messages still on their way to the recorder.
const DRAIN_WAIT: Duration = Duration::from_secs(1);

struct Run {
    client: Client,
    opts: RecordOptions,
    items: mpsc::Sender<Item>,
    subs: BTreeMap<String, Arc<Subscription>>,
    /// The sequence number of the last message handed over, per channel: what a stop waits to have caught up.
    last_seq: BTreeMap<String, u64>,
    streams: SelectAll<Messages>,
}

impl Run {
    async fn run(
        &mut self,
        existing: Vec<ChannelInfo>,
        mut events: broadcast::Receiver<ClientEvent>,
        mut stopped: oneshot::Receiver<()>,
    ) -> Result<(), RecordError> {
        for info in existing {
            self.offer(info).await?;
        }
        let mut flush = tokio::time::interval(self.opts.flush_every);
        flush.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                _ = &mut stopped => return self.drain().await,
                Some((name, data)) = self.streams.next(), if !self.streams.is_empty() => {
                    self.keep(name, data).await?;
                }
                event = events.recv() => match event {
                    Ok(ClientEvent::ChannelAdded(info)) => self.offer(info).await?,
                    Ok(ClientEvent::HeaderChanged { name, .. }) => {
                        // The new header comes with the channel's full description.
                        if self.subs.contains_key(&name) {
                            let info = self.client.channel(&name).await?;
                            hand_over(&self.items, Item::Channel(info)).await?;
                        }
                    }
                    Ok(_) => {}
                    // Missed events may include new channels: look again.
                    Err(broadcast::error::RecvError::Lagged(_)) => {
                        for info in self.client.channels().await? {
                            self.offer(info).await?;
                        }
                    }
                    Err(broadcast::error::RecvError::Closed) => return Ok(()),
                },
                _ = flush.tick() => hand_over(&self.items, Item::Flush).await?,
            }
        }
    }

    /// Subscribes to a channel if the selection wants it; a re-created channel gets its new description.
    async fn offer(&mut self, info: ChannelInfo) -> Result<(), RecordError> {
        if info.kind != ChannelKind::Stream || !self.opts.channels.matches(&info.name) {
            return Ok(());
        }
        let name = info.name.clone();
        // The description goes first, so that the writer knows the channel before its first message.
        hand_over(&self.items, Item::Channel(info)).await?;
        if self.subs.contains_key(&name) {
            return Ok(());
        }
        let sub = Arc::new(self.client.subscribe(&name).await?);
        self.subs.insert(name.clone(), sub.clone());
        let stream = futures_util::stream::unfold(sub, move |sub| {
            let name = name.clone();
            async move {
                let data = sub.recv().await?;
                Some(((name, data), sub))
            }
        });
        self.streams.push(Box::pin(stream));
        Ok(())
    }

    /// Hands one message over to the writer, noting how far its channel has come.
    async fn keep(&mut self, name: String, data: Data) -> Result<(), RecordError> {
        self.last_seq.insert(name.clone(), data.seq);
        let item = Item::Message {
            log_ns: hub_receive_ns(&data),
            name,
            data,
        };
        hand_over(&self.items, item).await
    }

    /// Keeps every message the hub had accepted on a recorded channel before the stop. The hub's count of a
    /// channel's messages is the sequence number of its last one, so each subscription is read until it has
    /// caught up with that count: messages still on their way through the hub's lanes arrive within
    /// milliseconds. A message dropped for falling behind never comes, so the wait is bounded by
    /// [`DRAIN_WAIT`]; a hub that no longer answers leaves only what has arrived.
    async fn drain(&mut self) -> Result<(), RecordError> {
        let subs: Vec<(String, Arc<Subscription>)> = self
            .subs
            .iter()
            .map(|(name, sub)| (name.clone(), sub.clone()))
            .collect();
        let published: BTreeMap<String, u64> =
            match tokio::time::timeout(DRAIN_WAIT, self.client.channels()).await {
                Ok(Ok(channels)) => channels
                    .into_iter()
                    .map(|c| (c.name, c.stats.msgs))
                    .collect(),
                _ => BTreeMap::new(),
            };
        let deadline = tokio::time::Instant::now() + DRAIN_WAIT;
        for (name, sub) in subs {
            while let Some(data) = sub.try_recv() {
                self.keep(name.clone(), data).await?;
            }
            let target = published.get(&name).copied().unwrap_or(0);
            while self.last_seq.get(&name).copied().unwrap_or(0) < target {
                match tokio::time::timeout_at(deadline, sub.recv()).await {
                    Ok(Some(data)) => self.keep(name.clone(), data).await?,
                    _ => break,
                }
            }
        }
        Ok(())
    }
}

/// A message's log time: when the hub received it (`Data.ts_us`, stamped by the hub as the publish arrives), or
/// the recorder's clock for a message without a stamp.
fn hub_receive_ns(data: &flow::Data) -> u64 {
    if data.ts_us > 0 {
        data.ts_us.saturating_mul(1000)
    } else {
        now_ns()
    }
}

/// Queues an item for the writer thread. (A free function, so that the future holds only the sender: `Run`'s
/// streams are `Send` but not `Sync`.)
async fn hand_over(items: &mpsc::Sender<Item>, item: Item) -> Result<(), RecordError> {
    items
        .send(item)
        .await
        .map_err(|_| RecordError::Writer("the writer thread has stopped".into()))
}

fn report(written: SinkReport, dropped: &BTreeMap<String, u64>) -> RecordReport {
    let mut channels: BTreeMap<String, ChannelReport> = written
        .channels
        .into_iter()
        .map(|(name, written)| {
            let dropped = dropped.get(&name).copied().unwrap_or(0);
            (name, ChannelReport { written, dropped })
        })
        .collect();
    for (name, d) in dropped {
        channels.entry(name.clone()).or_default().dropped = *d;
    }
    RecordReport {
        channels,
        annotations: written.annotations,
    }
}

/// Now, in nanoseconds since the Unix epoch.
fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}
