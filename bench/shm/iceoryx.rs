//! The floor: a plain iceoryx2 publisher / subscriber pair over shared memory, no hub. The publisher loans a slice
//! of the payload's size, writes the payload into it, sends, and wakes the subscribers through an iceoryx2 event
//! (the library's own way to block a subscriber instead of polling); N subscriber threads receive, touch the
//! stamp and the last byte, and return the sample.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::Context;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::stamp;
use crate::tally::Tally;

/// How long a subscriber sleeps in its listener before it looks at the stop flag again.
const POLL_STOP: Duration = Duration::from_millis(20);

/// The publisher with its subscriber threads running.
#[derive(Debug)]
pub struct IceRig {
    publisher: Publisher<ipc::Service, [u8], ()>,
    notifier: Notifier<ipc::Service>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    // The services live while the rig does.
    _events: event::PortFactory<ipc::Service>,
    _service: publish_subscribe::PortFactory<ipc::Service, [u8], ()>,
    _node: Node<ipc::Service>,
}

fn node() -> anyhow::Result<Node<ipc::Service>> {
    // No signal handlers: Ctrl-C ends the bench as it ends every other one.
    Ok(NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()?)
}

/// Creates the services `name` (payloads of `len` bytes) and `name/wake`, the publisher, and `n` subscriber
/// threads whose buffers hold `buffer` samples; returns once every subscriber is in place.
pub fn connect(
    name: &str,
    len: usize,
    n: usize,
    buffer: usize,
    tally: Arc<Tally>,
) -> anyhow::Result<IceRig> {
    // Errors only: without a config file iceoryx2 warns that it uses its defaults, which is what the bench wants.
    set_log_level(LogLevel::Error);
    let node = node()?;
    let service = node
        .service_builder(&ServiceName::new(name)?)
        .publish_subscribe::<[u8]>()
        .max_publishers(1)
        .max_subscribers(n)
        .max_nodes(n + 2)
        .history_size(0)
        .subscriber_max_buffer_size(buffer)
        .create()
        .with_context(|| format!("creating the iceoryx2 service {name}"))?;
    let wake_name = format!("{name}/wake");
    let events = node
        .service_builder(&ServiceName::new(&wake_name)?)
        .event()
        .max_notifiers(1)
        .max_listeners(n)
        .max_nodes(n + 2)
        .create()
        .with_context(|| format!("creating the iceoryx2 event service {wake_name}"))?;
    let publisher = service
        .publisher_builder()
        .initial_max_slice_len(len)
        .create()?;
    let notifier = events.notifier_builder().create()?;
    let stop = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready_rx) = mpsc::channel();
    let mut threads = Vec::new();
    for i in 0..n {
        let (name, wake_name) = (name.to_owned(), wake_name.clone());
        let (tally, stop, ready) = (tally.clone(), stop.clone(), ready_tx.clone());
        threads.push(
            std::thread::Builder::new()
                .name(format!("iox-sub-{i}"))
                .spawn(move || {
                    if let Err(e) = subscribe(&name, &wake_name, i, buffer, &tally, &stop, &ready) {
                        // Before it was ready the error goes to `connect`; after, it is printed.
                        if ready.send(Err(format!("{e:#}"))).is_err() {
                            eprintln!("shm-bench: iceoryx2 subscriber {i}: {e:#}");
                        }
                    }
                    tally.end(i);
                })?,
        );
    }
    drop(ready_tx);
    for _ in 0..n {
        match ready_rx.recv_timeout(Duration::from_secs(10)) {
            Ok(Ok(())) => {}
            Ok(Err(e)) => anyhow::bail!("an iceoryx2 subscriber failed to start: {e}"),
            Err(_) => anyhow::bail!("an iceoryx2 subscriber did not start within 10 s"),
        }
    }
    Ok(IceRig {
        publisher,
        notifier,
        stop,
        threads,
        _events: events,
        _service: service,
        _node: node,
    })
}

/// One subscriber thread: receives until told to stop, blocking on the event between bursts.
fn subscribe(
    name: &str,
    wake_name: &str,
    i: usize,
    buffer: usize,
    tally: &Tally,
    stop: &AtomicBool,
    ready: &mpsc::Sender<Result<(), String>>,
) -> anyhow::Result<()> {
    let node = node()?;
    let service = node
        .service_builder(&ServiceName::new(name)?)
        .publish_subscribe::<[u8]>()
        .open()?;
    let subscriber = service.subscriber_builder().buffer_size(buffer).create()?;
    let events = node
        .service_builder(&ServiceName::new(wake_name)?)
        .event()
        .open()?;
    let listener = events.listener_builder().create()?;
    let _ = ready.send(Ok(()));
    loop {
        while let Some(sample) = subscriber.receive()? {
            tally.record(i, sample.payload());
        }
        if stop.load(Ordering::SeqCst) {
            return Ok(());
        }
        // A notification sent between the last receive and this wait is kept, so none is missed.
        listener.timed_wait(|_| {}, POLL_STOP)?;
    }
}

impl IceRig {
    /// Loans a slice of the payload's size, writes `template` into it with the stamp, sends it and wakes the
    /// subscribers.
    pub fn send(&mut self, template: &[u8], seq: u64) -> anyhow::Result<()> {
        let sample = self.publisher.loan_slice_uninit(template.len())?;
        let mut sample = sample.write_from_slice(template);
        stamp::write(sample.payload_mut(), seq);
        sample.send()?;
        self.notifier.notify()?;
        Ok(())
    }

    /// Stops the subscriber threads and waits for them.
    pub fn close(self) {
        self.stop.store(true, Ordering::SeqCst);
        let _ = self.notifier.notify();
        for thread in self.threads {
            let _ = thread.join();
        }
    }
}
