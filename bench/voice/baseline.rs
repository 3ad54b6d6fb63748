//! PyPI's `piper-tts` as a process beside the bench (`piper_baseline.py`), speaking the same voice file as the
//! agent's Piper engine: one JSON request per line in, its first-chunk and total times out.

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

use anyhow::{Context, bail};
use serde_json::{Value, json};

/// One sentence spoken by piper-tts.
#[derive(Debug, Clone, Copy)]
pub struct Timing {
    pub first_ms: f64,
    pub total_ms: f64,
    pub samples: usize,
}

/// The running baseline.
#[derive(Debug)]
pub struct PiperTts {
    child: Child,
    input: ChildStdin,
    output: BufReader<ChildStdout>,
    pub load_ms: f64,
}

impl PiperTts {
    /// Starts `python piper_baseline.py VOICE JSON` and waits until the voice is loaded.
    pub fn start(python: &Path, voice: &Path, json: &Path) -> anyhow::Result<PiperTts> {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("voice/piper_baseline.py");
        let mut child = Command::new(python)
            .arg(&script)
            .arg(voice)
            .arg(json)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .with_context(|| {
                format!(
                    "starting {} (a venv with piper-tts==1.8.0; `make bench` makes models/piper-venv)",
                    python.display()
                )
            })?;
        let input = child.stdin.take().context("no stdin")?;
        let output = BufReader::new(child.stdout.take().context("no stdout")?);
        let mut baseline = PiperTts {
            child,
            input,
            output,
            load_ms: 0.0,
        };
        let ready = baseline.line()?;
        if ready["ready"] != true || ready["sample_rate"] != 22050 {
            bail!("piper-tts did not start: {ready}");
        }
        baseline.load_ms = ready["load_ms"].as_f64().unwrap_or(f64::NAN);
        Ok(baseline)
    }

    fn line(&mut self) -> anyhow::Result<Value> {
        let mut line = String::new();
        if self.output.read_line(&mut line)? == 0 {
            bail!("piper-tts ended unexpectedly");
        }
        serde_json::from_str(&line).with_context(|| format!("piper-tts said {line:?}"))
    }

    /// Speaks `text`; its times.
    pub fn speak(&mut self, text: &str) -> anyhow::Result<Timing> {
        writeln!(self.input, "{}", json!({ "text": text }))?;
        self.input.flush()?;
        let answer = self.line()?;
        let number = |key: &str| {
            answer[key]
                .as_f64()
                .with_context(|| format!("{key} in {answer}"))
        };
        Ok(Timing {
            first_ms: number("first_ms")?,
            total_ms: number("total_ms")?,
            samples: number("samples")? as usize,
        })
    }

    /// Ends the process; its peak RSS in MB.
    pub fn finish(mut self) -> anyhow::Result<f64> {
        writeln!(self.input, "{}", json!({ "quit": true }))?;
        self.input.flush()?;
        let last = self.line()?;
        let _ = self.child.wait();
        last["peak_rss_mb"]
            .as_f64()
            .context("no peak RSS from piper-tts")
    }
}
