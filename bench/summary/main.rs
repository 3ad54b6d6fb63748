//! `bench-summary`: rewrites the SUMMARY blocks of docs/benchmarks.md from the benches' saved output (`make bench`
//! tees each bench's stdout to `artifacts/bench/NAME.log`), each stamped with the day its log was written and the
//! commit, so that the figures there are those of the last run and say when it was.

use std::path::{Path, PathBuf};
use std::time::UNIX_EPOCH;

use agent_bench::summary::{
    Taken, block_names, current_commit, render, replace_block, summary_lines, utc_date,
};
use anyhow::{Context, bail};
use clap::Parser;

/// Command-line options. Paths are relative to the working directory, the repository root under `make`.
#[derive(Debug, Parser)]
#[command(about = "Rewrites docs/benchmarks.md's SUMMARY blocks from the benches' logs")]
struct Args {
    /// The folder of the benches' logs: block NAME is rewritten from NAME.log.
    #[arg(long, default_value = "artifacts/bench")]
    logs: PathBuf,
    /// The document whose `<!-- summary:NAME -->` blocks are rewritten.
    #[arg(long, default_value = "docs/benchmarks.md")]
    doc: PathBuf,
    /// The commit to stamp (default: `git describe --always --dirty` of the working directory).
    #[arg(long)]
    commit: Option<String>,
}

/// The UTC day `path` was last written: when its bench ran.
fn written_on(path: &Path) -> anyhow::Result<String> {
    let modified = std::fs::metadata(path)?.modified()?;
    let secs = modified.duration_since(UNIX_EPOCH)?.as_secs();
    Ok(utc_date(secs))
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let commit = args.commit.unwrap_or_else(current_commit);
    let mut doc = std::fs::read_to_string(&args.doc)
        .with_context(|| format!("reading {}", args.doc.display()))?;
    let names = block_names(&doc).with_context(|| format!("in {}", args.doc.display()))?;
    let mut failed = Vec::new();
    for name in &names {
        let log = args.logs.join(format!("{name}.log"));
        if !log.is_file() {
            eprintln!(
                "bench-summary: {name}: no {}, block left as it was",
                log.display()
            );
            continue;
        }
        let text =
            std::fs::read_to_string(&log).with_context(|| format!("reading {}", log.display()))?;
        let lines = summary_lines(&text);
        if lines.is_empty() {
            // A bench that printed no figure failed or was cut short; its old figures stay, and the run says so.
            eprintln!(
                "bench-summary: {name}: {} has no SUMMARY line, block left as it was",
                log.display()
            );
            failed.push(name.clone());
            continue;
        }
        let taken = Taken {
            date: written_on(&log).with_context(|| format!("dating {}", log.display()))?,
            commit: commit.clone(),
        };
        doc = replace_block(&doc, name, &render(&lines, &taken))?;
        println!(
            "bench-summary: {name}: {} lines of {} ({})",
            lines.len(),
            taken.date,
            log.display()
        );
    }
    // A log without a block is a bench whose figures the document does not show yet.
    if let Ok(entries) = std::fs::read_dir(&args.logs) {
        for entry in entries.flatten() {
            let path = entry.path();
            let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
            if path.extension().is_some_and(|e| e == "log") && !names.iter().any(|n| n == stem) {
                eprintln!(
                    "bench-summary: {} has no block <!-- summary:{stem} --> in {}",
                    path.display(),
                    args.doc.display()
                );
            }
        }
    }
    std::fs::write(&args.doc, &doc).with_context(|| format!("writing {}", args.doc.display()))?;
    if !failed.is_empty() {
        bail!("no SUMMARY line in the logs of {}", failed.join(", "));
    }
    Ok(())
}
