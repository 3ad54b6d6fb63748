//! The figures of a run and of the whole benchmark: stage breakdown, medians and p95, `SUMMARY` lines and the
//! Markdown report.

use std::fmt::Write as _;
use std::time::Instant;

use crate::speech_clip::Ending;

/// The voice-to-voice targets of the end-of-turn issue for whole turns: end of speech -> first reply PCM, tiny.en,
/// 2 cores.
pub const TARGET_P50_MS: f64 = 200.0;
pub const TARGET_P95_MS: f64 = 400.0;
/// A user talking over the agent stops it within this long of the voice onset.
pub const BARGE_IN_TARGET_MS: f64 = 300.0;
/// TCP hub hops on the critical path: audio in (microphone -> satellite), the transcript submitted to the relay,
/// the transcript published (relay -> hub; the brain and TTS modules sit in the server and read it in-process),
/// and the reply PCM out (hub -> listener).
pub const CRITICAL_HOPS: f64 = 4.0;

/// Wall-clock stamps of one utterance, all taken by the benchmark.
#[derive(Debug, Clone)]
pub struct RunFigures {
    /// The chunk holding the last voiced sample was published.
    pub end_of_speech: Instant,
    /// The `vad` end event arrived.
    pub vad_end: Instant,
    /// The final transcript arrived.
    pub transcript: Instant,
    /// The rule trace caused by hearing the transcript arrived.
    pub rules: Instant,
    /// The first reply PCM frame arrived.
    pub first_pcm: Instant,
    /// Whisper's inference time as the satellite reports it.
    pub processing_ms: u64,
    /// How the satellite got the text, as its transcript says.
    pub decode: Decode,
    /// The satellite's end of speech (the event's `at_ms`) minus ours (wall clock).
    pub vad_end_vs_ours_ms: f64,
    pub text: String,
    /// How the clip ends (set by the caller, which knows the clip).
    pub ending: Ending,
}

/// How a transcript was decoded (its `speculative`, `full_window_retry` and `turn` fields).
#[derive(Debug, Clone, Default)]
pub struct Decode {
    /// Decoded during the hangover, from the audio the utterance paused with.
    pub speculative: bool,
    /// The fitted window looped; the text is from a second decode with the full window.
    pub full_window_retry: bool,
    /// The satellite's end-of-turn verdict on the pause the utterance ended at.
    pub turn: Option<String>,
}

fn ms(from: Instant, to: Instant) -> f64 {
    to.saturating_duration_since(from).as_secs_f64() * 1000.0
}

impl RunFigures {
    pub fn voice_to_voice(&self) -> f64 {
        ms(self.end_of_speech, self.first_pcm)
    }
    pub fn hangover(&self) -> f64 {
        ms(self.end_of_speech, self.vad_end)
    }
    pub fn asr(&self) -> f64 {
        ms(self.vad_end, self.transcript)
    }
    pub fn rules(&self) -> f64 {
        ms(self.transcript, self.rules)
    }
    pub fn first_chunk(&self) -> f64 {
        ms(self.rules, self.first_pcm)
    }

    /// One line for the progress output.
    pub fn line(&self) -> String {
        format!(
            "v2v {:>6.1} ms = vad {:>5.1} + asr {:>5.1} (whisper {:>3} ms{}{}, turn {}) + rules {:>4.1} + tts {:>4.1}   \"{}\"",
            self.voice_to_voice(),
            self.hangover(),
            self.asr(),
            self.processing_ms,
            if self.decode.speculative {
                ", speculative"
            } else {
                ""
            },
            if self.decode.full_window_retry {
                ", full-window retry"
            } else {
                ""
            },
            self.decode.turn.as_deref().unwrap_or("unjudged"),
            self.rules(),
            self.first_chunk(),
            self.text
        )
    }
}

/// Everything measured.
#[derive(Debug, Default)]
pub struct Figures {
    pub runs: Vec<RunFigures>,
    pub lost: usize,
    /// Single hub hops (ms).
    pub hop: Vec<f64>,
    /// The barge-in runs.
    pub barge_ins: crate::barge_in::BargeIns,
    /// The machine's load average before and after the runs: whisper's threads spin while they wait for each
    /// other, so other processes on these two cores inflate the ASR stage a lot; the figures need this beside them.
    pub load: (String, String),
}

/// The 1, 5 and 15 minute load averages, as `/proc/loadavg` has them.
pub fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg").map_or_else(
        |_| "unknown".to_owned(),
        |l| l.split_whitespace().take(3).collect::<Vec<_>>().join(" "),
    )
}

/// The `q` quantile (nearest rank) of `values`; 0 when empty.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

struct Stage {
    name: &'static str,
    how: &'static str,
    values: Vec<f64>,
}

impl Figures {
    /// The runs that said a whole turn: the targets are for them.
    fn turns(&self) -> impl Iterator<Item = &RunFigures> {
        self.runs.iter().filter(|r| r.ending == Ending::Turn)
    }

    fn stages(&self) -> Vec<Stage> {
        let of = |f: fn(&RunFigures) -> f64| self.turns().map(f).collect::<Vec<_>>();
        vec![
            Stage {
                name: "voice_to_voice",
                how: "last voiced chunk published -> first reply PCM frame received",
                values: of(RunFigures::voice_to_voice),
            },
            Stage {
                name: "vad_hangover",
                how: "last voiced chunk published -> `vad` end event received (the end of turn: confirmation silence or verdict for a complete turn, else the hangover; VAD framing, resampler)",
                values: of(RunFigures::hangover),
            },
            Stage {
                name: "asr",
                how: "`vad` end received -> final transcript received (what is left of whisper's decode, submit, relay)",
                values: of(RunFigures::asr),
            },
            Stage {
                name: "asr_inference",
                how: "the transcript's `processing_ms` (whisper alone; a speculative decode starts at the pause, when the trailing silence holds the post-roll, and its verdict ends a complete turn at once)",
                values: of(|r| r.processing_ms as f64),
            },
            Stage {
                name: "rules",
                how: "transcript received -> rule trace received (brain step, trace published)",
                values: of(RunFigures::rules),
            },
            Stage {
                name: "first_tts_chunk",
                how: "rule trace received -> first reply PCM received (say request, the voice's first chunk)",
                values: of(RunFigures::first_chunk),
            },
            Stage {
                name: "hub_hop",
                how: "one 882-byte message, TCP client -> hub -> TCP client, measured on its own",
                values: self.hop.clone(),
            },
        ]
    }

    fn summary_lines(&self) -> Vec<String> {
        let stages = self.stages();
        let v2v = &stages[0].values;
        let p50 = quantile(v2v, 0.5);
        let p95 = quantile(v2v, 0.95);
        let met = |v: f64, target: f64| if v <= target { "met" } else { "missed" };
        let mut lines = vec![
            format!(
                "SUMMARY voice_to_voice_p50: {p50:.0} ms (whole turns; target <= {TARGET_P50_MS:.0} ms, ratio {:.2}: {})",
                p50 / TARGET_P50_MS,
                met(p50, TARGET_P50_MS)
            ),
            format!(
                "SUMMARY voice_to_voice_p95: {p95:.0} ms (whole turns; target <= {TARGET_P95_MS:.0} ms, ratio {:.2}: {})",
                p95 / TARGET_P95_MS,
                met(p95, TARGET_P95_MS)
            ),
        ];
        let mid: Vec<f64> = self
            .runs
            .iter()
            .filter(|r| r.ending == Ending::MidSentence)
            .map(RunFigures::voice_to_voice)
            .collect();
        if !mid.is_empty() {
            lines.push(format!(
                "SUMMARY voice_to_voice_mid_sentence_p50: {:.0} ms ({} phrases cut inside a sentence, held open for the rest of it; whole turns {p50:.0} ms, ratio {:.2})",
                quantile(&mid, 0.5),
                mid.len(),
                quantile(&mid, 0.5) / p50.max(1e-9)
            ));
        }
        let verdicts = |ending: Ending| {
            let mut counts = std::collections::BTreeMap::<&str, usize>::new();
            for r in self.runs.iter().filter(|r| r.ending == ending) {
                *counts
                    .entry(r.decode.turn.as_deref().unwrap_or("unjudged"))
                    .or_default() += 1;
            }
            counts
                .iter()
                .map(|(k, n)| format!("{k} {n}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        lines.push(format!(
            "SUMMARY voice_to_voice_turn_verdicts: whole turns: {}; mid-sentence: {}",
            verdicts(Ending::Turn),
            verdicts(Ending::MidSentence)
        ));
        let b = &self.barge_ins;
        if !b.onset_to_stop.is_empty() || b.missed > 0 {
            let p50 = quantile(&b.onset_to_stop, 0.5);
            let p95 = quantile(&b.onset_to_stop, 0.95);
            lines.push(format!(
                "SUMMARY barge_in_onset_to_stop_p50: {p50:.0} ms (p95 {p95:.0} ms; target <= {BARGE_IN_TARGET_MS:.0} ms, ratio {:.2}: {}; {} runs, {} missed; vad start p50 {:.0} ms)",
                p95 / BARGE_IN_TARGET_MS,
                met(p95, BARGE_IN_TARGET_MS),
                b.onset_to_stop.len() + b.missed,
                b.missed,
                quantile(&b.onset_to_vad_start, 0.5)
            ));
            lines.push(format!(
                "SUMMARY barge_in_bursts: {} of {} bursts of 150 ms stopped the reply (target 0)",
                b.burst_stops, b.bursts
            ));
        }
        for s in &stages[1..] {
            let share = quantile(&s.values, 0.5) / p50.max(1e-9);
            lines.push(format!(
                "SUMMARY voice_to_voice_{}_p50: {:.1} ms (p95 {:.1} ms, share of the median {:.2})",
                s.name,
                quantile(&s.values, 0.5),
                quantile(&s.values, 0.95),
                share
            ));
        }
        let hop = quantile(&self.hop, 0.5);
        lines.push(format!(
            "SUMMARY voice_to_voice_transport_p50: {:.1} ms ({CRITICAL_HOPS:.0} hub hops x {hop:.2} ms, share of the median {:.3})",
            CRITICAL_HOPS * hop,
            CRITICAL_HOPS * hop / p50.max(1e-9)
        ));
        lines
    }

    fn table(&self) -> String {
        let mut t = String::from(
            "| stage | median ms | p95 ms | how it is measured |\n|---|---|---|---|\n",
        );
        for s in self.stages() {
            let _ = writeln!(
                t,
                "| {} | {:.1} | {:.1} | {} |",
                s.name,
                quantile(&s.values, 0.5),
                quantile(&s.values, 0.95),
                s.how
            );
        }
        t
    }

    /// Prints the breakdown and the `SUMMARY` lines.
    pub fn print(&self, setup: &str) {
        println!();
        println!(
            "{setup}; {} runs measured, {} lost",
            self.runs.len(),
            self.lost
        );
        print!("{}", self.table());
        let offsets: Vec<f64> = self.runs.iter().map(|r| r.vad_end_vs_ours_ms).collect();
        println!(
            "the satellite's end of speech is {:.0} ms (median) from ours",
            quantile(&offsets, 0.5)
        );
        for line in self.summary_lines() {
            println!("{line}");
        }
    }

    /// The report for `--write`.
    pub fn markdown(&self, setup: &str) -> String {
        let offsets: Vec<f64> = self.runs.iter().map(|r| r.vad_end_vs_ours_ms).collect();
        format!(
            "## Figures ({setup})\n\nWritten by `voice-latency --write`; {} runs measured, {} lost; load average {} \
             before the runs, {} after. The satellite's own end of speech (`at_ms` of the `vad` end event) is {:.0} ms \
             (median) from the benchmark's.\n\n{}\n```\n{}\n```\n",
            self.runs.len(),
            self.lost,
            self.load.0,
            self.load.1,
            quantile(&offsets, 0.5),
            self.table(),
            self.summary_lines().join("\n")
        )
    }
}

/// Marks the part of the report the benchmark rewrites; the method and analysis around it are kept.
const BEGIN: &str = "<!-- voice-latency figures: written by the benchmark -->";
const END: &str = "<!-- end of voice-latency figures -->";

/// Puts `figures` between the markers of the report at `path`; a report without them gets them at its end, a new
/// report holds only them.
pub fn write_figures(path: &std::path::Path, figures: &str) -> anyhow::Result<()> {
    use anyhow::Context as _;
    let block = format!("{BEGIN}\n{figures}{END}\n");
    let old = std::fs::read_to_string(path).unwrap_or_default();
    let new = match (old.find(BEGIN), old.find(END)) {
        (Some(b), Some(e)) if b < e => {
            // One blank line between the figures and what follows them.
            let rest = old[e + END.len()..].trim_start_matches('\n');
            let gap = if rest.is_empty() { "" } else { "\n" };
            format!("{}{block}{gap}{rest}", &old[..b])
        }
        _ if old.trim().is_empty() => format!("# Voice-to-voice latency\n\n{block}"),
        _ => format!("{}\n\n{block}", old.trim_end()),
    };
    std::fs::write(path, new).with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_replace_only_their_block() -> anyhow::Result<()> {
        let dir = std::env::temp_dir().join(format!("voice-latency-report-{}", std::process::id()));
        std::fs::create_dir_all(&dir)?;
        let path = dir.join("report.md");
        write_figures(&path, "one\n")?;
        let first = std::fs::read_to_string(&path)?;
        std::fs::write(&path, format!("intro\n{first}analysis\n"))?;
        write_figures(&path, "two\n")?;
        let second = std::fs::read_to_string(&path)?;
        assert!(second.starts_with("intro\n# Voice"), "{second}");
        assert!(
            second.contains("two\n") && !second.contains("one\n"),
            "{second}"
        );
        assert!(second.ends_with("-->\n\nanalysis\n"), "{second}");
        std::fs::remove_dir_all(&dir)?;
        Ok(())
    }

    #[test]
    fn quantiles_by_nearest_rank() {
        let v: Vec<f64> = (1..=20).map(f64::from).collect();
        assert_eq!(quantile(&v, 0.5), 10.0);
        assert_eq!(quantile(&v, 0.95), 19.0);
        assert_eq!(quantile(&[], 0.5), 0.0);
    }
}
