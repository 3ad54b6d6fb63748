//! Satellites as separate processes for the ASR benchmark: N workers started as `asr-bench bench-worker`
//! (`crate::worker`) with `whisper-sat run`'s default recognition flags (so they join the machine's core share
//! exactly as `whisper-sat run` does), fed utterances from one queue.
//!
//! The jobs travel once, in a file (`crate::jobs`); after that the parent writes a job's index to a worker's stdin
//! and the worker answers `done INDEX PROCESSING_MS THREADS WAIT_MS` on its stdout when the decode has finished.
//! `ready` on stdout says the model is loaded and warm.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::Context;

/// One worker process and its pipes.
struct Worker {
    child: Child,
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
}

/// What a worker said about one job.
#[derive(Debug, Clone, Copy)]
pub struct Done {
    /// From handing the job over to hearing it was done.
    pub round_trip: Duration,
    pub threads: usize,
    pub core_wait: Duration,
}

impl Worker {
    fn send(&mut self, index: usize) -> anyhow::Result<()> {
        writeln!(self.stdin, "{index}")?;
        self.stdin.flush()?;
        Ok(())
    }

    fn wait_done(&mut self, sent: Instant) -> anyhow::Result<Done> {
        let mut line = String::new();
        anyhow::ensure!(
            self.stdout.read_line(&mut line)? > 0,
            "a bench worker exited"
        );
        let round_trip = sent.elapsed();
        let fields: Vec<&str> = line.split_whitespace().collect();
        let [_, _, _, threads, wait] = fields[..] else {
            anyhow::bail!("unexpected worker answer {line:?}");
        };
        Ok(Done {
            round_trip,
            threads: threads.parse()?,
            core_wait: Duration::from_millis(wait.parse()?),
        })
    }

    fn run(&mut self, index: usize) -> anyhow::Result<Done> {
        let sent = Instant::now();
        self.send(index)?;
        self.wait_done(sent)
    }
}

/// N satellites started with default flags, sharing one core share directory of their own.
pub struct Fleet {
    workers: Vec<Worker>,
}

impl Fleet {
    /// Starts `n` workers on `jobs_file` and waits until each is warm. `share_dir` keeps the bench's core share
    /// apart from satellites that may be running on the machine; every other flag is the default.
    pub fn start(
        n: usize,
        model: &Path,
        jobs_file: &Path,
        share_dir: &Path,
    ) -> anyhow::Result<Self> {
        // The worker is this benchmark's own `bench-worker` subcommand.
        let exe = std::env::current_exe().context("locating asr-bench")?;
        let mut workers = Vec::new();
        for _ in 0..n {
            let mut child = Command::new(&exe)
                .arg("bench-worker")
                .arg("--jobs")
                .arg(jobs_file)
                .arg("--model")
                .arg(model)
                .arg("--core-share-dir")
                .arg(share_dir)
                .stdin(Stdio::piped())
                .stdout(Stdio::piped())
                .stderr(Stdio::inherit())
                .spawn()
                .context("starting a bench worker")?;
            let stdin = child.stdin.take().context("worker stdin")?;
            let stdout = BufReader::new(child.stdout.take().context("worker stdout")?);
            workers.push(Worker {
                child,
                stdin,
                stdout,
            });
        }
        for w in &mut workers {
            let mut line = String::new();
            w.stdout.read_line(&mut line)?;
            anyhow::ensure!(line.trim() == "ready", "bench worker said {line:?}");
        }
        Ok(Self { workers })
    }

    /// Seconds for the fleet to get through `jobs` job indices, each worker taking the next one when it is free.
    pub fn throughput(&mut self, jobs: usize) -> anyhow::Result<f64> {
        let queue = Mutex::new(0..jobs);
        let started = Instant::now();
        std::thread::scope(|s| -> anyhow::Result<()> {
            let handles: Vec<_> = self
                .workers
                .iter_mut()
                .map(|w| {
                    let queue = &queue;
                    s.spawn(move || -> anyhow::Result<()> {
                        loop {
                            let next = queue
                                .lock()
                                .map_err(|_| anyhow::anyhow!("queue poisoned"))?
                                .next();
                            let Some(index) = next else { return Ok(()) };
                            w.run(index)?;
                        }
                    })
                })
                .collect();
            for h in handles {
                h.join()
                    .map_err(|_| anyhow::anyhow!("worker thread panicked"))??;
            }
            Ok(())
        })?;
        Ok(started.elapsed().as_secs_f64())
    }

    /// Job `index` on worker 0 alone.
    pub fn alone(&mut self, index: usize) -> anyhow::Result<Done> {
        self.workers[0].run(index)
    }

    /// Job `long` on worker 0, then, `head_start` later, job `short` on worker 1: both answers.
    pub fn beside(
        &mut self,
        long: usize,
        short: usize,
        head_start: Duration,
    ) -> anyhow::Result<(Done, Done)> {
        let [first, second, ..] = &mut self.workers[..] else {
            anyhow::bail!("two workers needed");
        };
        let long_sent = Instant::now();
        first.send(long)?;
        std::thread::sleep(head_start);
        let short_done = second.run(short)?;
        let long_done = first.wait_done(long_sent)?;
        Ok((long_done, short_done))
    }
}

impl Fleet {
    /// Peak resident memory of each worker process so far, in MB.
    pub fn peak_rss_mb(&self) -> Vec<f64> {
        self.workers
            .iter()
            .map(|w| crate::clips::process_peak_rss_mb(&w.child.id().to_string()))
            .collect()
    }
}

impl Drop for Fleet {
    fn drop(&mut self) {
        for w in &mut self.workers {
            // Closing stdin ends the worker's loop; kill in case it is stuck in a decode.
            let _ = w.stdin.flush();
            let _ = w.child.kill();
            let _ = w.child.wait();
            let mut rest = Vec::new();
            let _ = w.stdout.read_to_end(&mut rest);
        }
    }
}
