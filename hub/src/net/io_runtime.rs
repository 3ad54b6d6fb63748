//! The runtime that serves the hub's TCP and Unix-socket connections, on threads of its own.
//!
//! A publish is fanned out by the task that read it: it pushes the message into every subscriber's outbox and
//! wakes each subscriber's writer task. On a multi-threaded runtime most of those wakes land on another worker,
//! which must be woken through the kernel and then steals the writers; with one thread, as Redis does it, the
//! writers run right after the reader on the same thread and no wake leaves it. On two cores that made the hub
//! roughly twice as fast for camera frames (docs/bench-hub.md). `hub.io_threads` raises the count for machines
//! with many busy satellites and cores to spare.
//!
//! Modules, the HTTP server and WebSocket links stay on the main runtime; outboxes are thread-safe, so a module
//! publishing to a socket subscriber just wakes the writer over here.

use std::io;
use std::time::Duration;

use tokio::runtime::{Builder, Handle, Runtime};
use tokio::sync::oneshot;

/// How long connection tasks still get to run after the listeners have stopped.
const STOP_GRACE: Duration = Duration::from_secs(1);

/// A runtime on its own thread(s); dropped or stopped, it ends its tasks.
#[derive(Debug)]
pub struct IoRuntime {
    handle: Handle,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl IoRuntime {
    /// Starts a runtime with `threads` workers (one: a current-thread runtime on a thread of its own).
    pub fn start(threads: usize) -> io::Result<IoRuntime> {
        let runtime: Runtime = if threads <= 1 {
            Builder::new_current_thread().enable_all().build()?
        } else {
            Builder::new_multi_thread()
                .worker_threads(threads)
                .thread_name("hub-io")
                .enable_all()
                .build()?
        };
        let handle = runtime.handle().clone();
        let (stop, stopped) = oneshot::channel::<()>();
        let thread = std::thread::Builder::new()
            .name("hub-io".into())
            .spawn(move || {
                // A current-thread runtime runs its tasks only inside `block_on`, so this thread drives them
                // until told to stop (or until the server is dropped, which drops the sender).
                runtime.block_on(async {
                    let _ = stopped.await;
                });
                runtime.shutdown_timeout(STOP_GRACE);
            })?;
        Ok(IoRuntime {
            handle,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// Where to spawn connection work, and the context in which to create sockets so that they register with
    /// this runtime's reactor.
    pub fn handle(&self) -> &Handle {
        &self.handle
    }

    /// Ends the runtime's tasks and waits for its thread.
    pub async fn stop(mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            // Joining blocks, so it happens off the async workers.
            let _ = tokio::task::spawn_blocking(move || thread.join()).await;
        }
    }
}

impl Drop for IoRuntime {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
    }
}
