//! One generator as a child process: started, waited for until its model is loaded, asked one request at a time over
//! its stdin, and closed at the end for its peak RSS.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

use anyhow::{Context, bail};
use serde::de::DeserializeOwned;

use crate::wire::{Finished, Ready, Reply, Request};

pub struct Worker {
    pub name: &'static str,
    pub load_s: f64,
    child: Child,
    stdin: Option<ChildStdin>,
    stdout: BufReader<ChildStdout>,
}

impl Worker {
    /// Starts `command` and waits for its ready line.
    pub fn start(name: &'static str, mut command: Command) -> anyhow::Result<Worker> {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .with_context(|| format!("starting {name}: {command:?}"))?;
        let stdin = child.stdin.take().context("child stdin")?;
        let stdout = BufReader::new(child.stdout.take().context("child stdout")?);
        let mut worker = Worker {
            name,
            load_s: 0.0,
            child,
            stdin: Some(stdin),
            stdout,
        };
        let ready: Ready = worker.read()?;
        if !ready.ready {
            bail!("{name} did not get ready");
        }
        worker.load_s = ready.load_s;
        Ok(worker)
    }

    /// One generation, timed inside the worker.
    pub fn ask(&mut self, request: &Request) -> anyhow::Result<Reply> {
        let stdin = self.stdin.as_mut().context("worker already closed")?;
        writeln!(stdin, "{}", serde_json::to_string(request)?)?;
        stdin.flush()?;
        self.read()
    }

    /// Closes its input and returns its peak RSS in KiB.
    pub fn finish(mut self) -> anyhow::Result<u64> {
        drop(self.stdin.take());
        let finished: Finished = self.read()?;
        let status = self.child.wait()?;
        if !status.success() {
            bail!("{} exited with {status}", self.name);
        }
        Ok(finished.peak_rss_kb)
    }

    /// The next JSON line of its output; other lines (a library's stray print) are shown and skipped.
    fn read<T: DeserializeOwned>(&mut self) -> anyhow::Result<T> {
        loop {
            let mut line = String::new();
            if self.stdout.read_line(&mut line)? == 0 {
                bail!("{} ended its output early (its error is above)", self.name);
            }
            if line.trim_start().starts_with('{') {
                return serde_json::from_str(&line)
                    .with_context(|| format!("{} answered {line:?}", self.name));
            }
            eprint!("{}: {line}", self.name);
        }
    }
}
