//! One satellite process of the fleets: `asr-bench bench-worker`, started by `crate::fleet`. It loads the model with
//! `whisper-sat run`'s recognition flags (`whisper_sat::recognition`), so it joins the machine's core share exactly
//! as a running satellite does, and decodes the jobs its parent names.
//!
//! `ready` on stdout says the model is loaded and warm; then the parent writes a job's index to stdin and the
//! worker answers `done INDEX PROCESSING_MS THREADS WAIT_MS` on stdout when the decode has finished.

use std::io::{BufRead, Write};
use std::path::PathBuf;

use anyhow::Context;
use whisper_sat::recognition::RecognitionArgs;
use whisper_sat::transcriber::Transcriber;

use crate::jobs::read_jobs;

/// `asr-bench bench-worker`'s flags: the jobs file, and `whisper-sat run`'s recognition flags.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The jobs file the bench wrote (`crate::jobs`).
    #[arg(long)]
    jobs: PathBuf,
    #[command(flatten)]
    recognition: RecognitionArgs,
}

/// Decodes the jobs the parent names, one at a time.
pub fn run(args: Args) -> anyhow::Result<()> {
    let jobs = read_jobs(&args.jobs)?;
    let mut transcriber =
        Transcriber::load(&args.recognition.model(), args.recognition.transcriber())?;
    if let Some(share) = args.recognition.core_share()? {
        transcriber.share_cores(share);
    }
    if let Some(first) = jobs.first() {
        transcriber.decode(first)?;
    }
    let mut out = std::io::stdout().lock();
    writeln!(out, "ready")?;
    out.flush()?;
    for line in std::io::stdin().lock().lines() {
        let index: usize = line?.trim().parse().context("job index")?;
        let job = jobs.get(index).context("no such job")?;
        let d = transcriber.decode(job)?;
        writeln!(
            out,
            "done {index} {} {} {}",
            d.processing.as_millis(),
            d.threads,
            d.core_wait.as_millis()
        )?;
        out.flush()?;
    }
    Ok(())
}
