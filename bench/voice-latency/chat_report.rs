//! The figures of the chat phase: open questions answered by `llm-sat`, voice to voice and its breakdown (transcript,
//! the model's `prompt` event, its first `sentence`, the first reply PCM), against their own targets, as `SUMMARY`
//! lines.

use std::time::Instant;

use serde_json::Value;

use crate::report::{RunFigures, quantile};

/// Voice-to-voice targets for a turn the rules hand to the language model (end of speech -> first reply PCM).
pub const CHAT_TARGET_P50_MS: f64 = 500.0;
pub const CHAT_TARGET_P95_MS: f64 = 800.0;

/// Stamps of one open question, all taken by the benchmark, and the model's own figures for the turn.
#[derive(Debug, Clone)]
pub struct ChatRunFigures {
    /// End of speech, `vad` end, transcript, rule trace and first reply PCM, as for the rule path.
    pub base: RunFigures,
    /// The turn's `prompt` event arrived on `Agent.chat.reply`.
    pub prompt: Instant,
    /// Its first `sentence` event arrived.
    pub first_sentence: Instant,
    /// Its `end` event arrived.
    pub end: Instant,
    /// Prompt tokens, of them from the cache of the previous prompt, tokens generated, and the model's own time
    /// from the request to the first token (from the `end` event's stats).
    pub prompt_tokens: u64,
    pub cached_tokens: u64,
    pub tokens: u64,
    pub first_token_ms: u64,
    /// The first sentence, as spoken.
    pub sentence: String,
    /// The reply was started at the pause, on the speculative transcript, and kept (`stats.speculated`).
    pub kept_early: bool,
    /// The tokens of each speculative turn dropped during the run (started on words the final transcript changed).
    pub dropped_tokens: Vec<u64>,
    /// The knowledge folder's passages the turn's facts quoted (the trace's `passage` steps): the files.
    pub passages: Vec<String>,
}

/// One figure of a run, in milliseconds.
type Measure = fn(&ChatRunFigures) -> f64;

fn ms(from: Instant, to: Instant) -> f64 {
    to.saturating_duration_since(from).as_secs_f64() * 1000.0
}

impl ChatRunFigures {
    pub fn new(
        base: RunFigures,
        prompt: Instant,
        first_sentence: Instant,
        end: Instant,
        stats: &Value,
        sentence: String,
        dropped_tokens: Vec<u64>,
    ) -> ChatRunFigures {
        let stat = |name: &str| stats[name].as_u64().unwrap_or(0);
        ChatRunFigures {
            base,
            prompt,
            first_sentence,
            end,
            prompt_tokens: stat("prompt_tokens"),
            cached_tokens: stat("cached_tokens"),
            tokens: stat("tokens"),
            first_token_ms: stat("first_token_ms"),
            sentence,
            kept_early: stats["speculated"] == true,
            dropped_tokens,
            passages: Vec::new(),
        }
    }

    /// The same run, with the knowledge passages its facts quoted.
    pub fn with_passages(self, passages: Vec<String>) -> ChatRunFigures {
        ChatRunFigures { passages, ..self }
    }

    pub fn voice_to_voice(&self) -> f64 {
        self.base.voice_to_voice()
    }
    /// End of speech -> final transcript received (end of turn and what is left of the decode).
    pub fn transcript(&self) -> f64 {
        ms(self.base.end_of_speech, self.base.transcript)
    }
    /// Transcript -> `prompt` event (rule step, the chat call to the satellite, the prompt built and published).
    pub fn prompt(&self) -> f64 {
        ms(self.base.transcript, self.prompt)
    }
    /// `prompt` -> first `sentence` event (prompt evaluation, generation up to the first sentence's end).
    pub fn first_sentence(&self) -> f64 {
        ms(self.prompt, self.first_sentence)
    }
    /// First `sentence` -> first reply PCM (the brain's `say`, the voice's first chunk).
    pub fn first_pcm(&self) -> f64 {
        ms(self.first_sentence, self.base.first_pcm)
    }
    /// `prompt` -> `end`: the whole reply's generation.
    pub fn generation(&self) -> f64 {
        ms(self.prompt, self.end)
    }

    /// One line for the progress output.
    pub fn line(&self) -> String {
        format!(
            "v2v {:>6.1} ms = transcript {:>5.1} + prompt {:>5.1} + first sentence {:>6.1} (prompt {} tokens, {} cached; first token {} ms) + tts {:>4.1}; reply {} tokens in {:.0} ms{}{}{}   \"{}\" -> \"{}\"",
            self.voice_to_voice(),
            self.transcript(),
            self.prompt(),
            self.first_sentence(),
            self.prompt_tokens,
            self.cached_tokens,
            self.first_token_ms,
            self.first_pcm(),
            self.tokens,
            self.generation(),
            if self.kept_early {
                "; started at the pause"
            } else {
                ""
            },
            if self.dropped_tokens.is_empty() {
                String::new()
            } else {
                format!(
                    "; dropped early replies of {:?} tokens",
                    self.dropped_tokens
                )
            },
            if self.passages.is_empty() {
                String::new()
            } else {
                format!("; passage from {}", self.passages.join(", "))
            },
            self.base.text,
            self.sentence
        )
    }
}

/// Everything the chat phase measured.
#[derive(Debug, Default)]
pub struct ChatFigures {
    pub runs: Vec<ChatRunFigures>,
    pub lost: usize,
    /// `VmHWM` of the `llm-sat` process at the end, in kB (`None` when it could not be read).
    pub peak_rss_kb: Option<u64>,
}

impl ChatFigures {
    fn of(&self, f: Measure) -> Vec<f64> {
        self.runs.iter().map(f).collect()
    }

    pub fn summary_lines(&self) -> Vec<String> {
        let v2v = self.of(ChatRunFigures::voice_to_voice);
        let (p50, p95) = (quantile(&v2v, 0.5), quantile(&v2v, 0.95));
        let met = |v: f64, target: f64| if v <= target { "met" } else { "missed" };
        let mut lines = vec![
            format!(
                "SUMMARY voice_to_voice_chat_p50: {p50:.0} ms (open questions answered by llm-sat, {} runs, {} lost; target <= {CHAT_TARGET_P50_MS:.0} ms, ratio {:.2}: {})",
                self.runs.len(),
                self.lost,
                p50 / CHAT_TARGET_P50_MS,
                met(p50, CHAT_TARGET_P50_MS)
            ),
            format!(
                "SUMMARY voice_to_voice_chat_p95: {p95:.0} ms (open questions answered by llm-sat; target <= {CHAT_TARGET_P95_MS:.0} ms, ratio {:.2}: {})",
                p95 / CHAT_TARGET_P95_MS,
                met(p95, CHAT_TARGET_P95_MS)
            ),
        ];
        let stages: [(&str, &str, Measure); 5] = [
            (
                "transcript",
                "end of speech -> final transcript",
                ChatRunFigures::transcript,
            ),
            (
                "prompt",
                "transcript -> prompt event",
                ChatRunFigures::prompt,
            ),
            (
                "first_sentence",
                "prompt event -> first sentence event",
                ChatRunFigures::first_sentence,
            ),
            (
                "first_pcm",
                "first sentence event -> first reply PCM",
                ChatRunFigures::first_pcm,
            ),
            (
                "generation",
                "prompt event -> end event, not on the critical path",
                ChatRunFigures::generation,
            ),
        ];
        for (name, how, f) in stages {
            let values = self.of(f);
            lines.push(format!(
                "SUMMARY voice_to_voice_chat_{name}_p50: {:.1} ms (p95 {:.1} ms, share of the median {:.2}; {how})",
                quantile(&values, 0.5),
                quantile(&values, 0.95),
                quantile(&values, 0.5) / p50.max(1e-9)
            ));
        }
        let first_token = self.of(|r| r.first_token_ms as f64);
        let prompt_tokens = self.of(|r| r.prompt_tokens as f64);
        let cached = self.of(|r| r.cached_tokens as f64);
        lines.push(format!(
            "SUMMARY voice_to_voice_chat_model_first_token_p50: {:.0} ms (p95 {:.0} ms; llm-sat's own request -> first token; prompt {:.0} tokens, {:.0} of them cached, medians)",
            quantile(&first_token, 0.5),
            quantile(&first_token, 0.95),
            quantile(&prompt_tokens, 0.5),
            quantile(&cached, 0.5)
        ));
        let with_passage = self.runs.iter().filter(|r| !r.passages.is_empty()).count();
        lines.push(format!(
            "SUMMARY voice_to_voice_chat_knowledge_passages: {with_passage} of {} open questions carried a passage of the knowledge folder in their facts ({:.0}%)",
            self.runs.len(),
            100.0 * with_passage as f64 / self.runs.len().max(1) as f64
        ));
        let kept = self.runs.iter().filter(|r| r.kept_early).count();
        let dropped: Vec<u64> = self
            .runs
            .iter()
            .flat_map(|r| r.dropped_tokens.iter().copied())
            .collect();
        let early = kept + dropped.len();
        lines.push(format!(
            "SUMMARY voice_to_voice_chat_preemptive_kept: {:.0}% ({kept} of {early} replies started at a pause were kept, {} dropped; {} of {} turns answered by a reply started early)",
            100.0 * kept as f64 / early.max(1) as f64,
            dropped.len(),
            kept,
            self.runs.len()
        ));
        lines.push(format!(
            "SUMMARY voice_to_voice_chat_preemptive_wasted_tokens: {:.1} per turn ({} tokens generated by dropped early replies over {} turns)",
            dropped.iter().sum::<u64>() as f64 / self.runs.len().max(1) as f64,
            dropped.iter().sum::<u64>(),
            self.runs.len()
        ));
        lines.push(match self.peak_rss_kb {
            Some(kb) => format!(
                "SUMMARY llm_sat_peak_rss: {} MB (VmHWM of the llm-sat process at the end)",
                kb.div_ceil(1024)
            ),
            None => {
                "SUMMARY llm_sat_peak_rss: unknown (its /proc status could not be read)".to_owned()
            }
        });
        lines
    }

    /// Prints the runs' count and the `SUMMARY` lines.
    pub fn print(&self, setup: &str) {
        println!();
        println!(
            "chat phase ({setup}); {} runs measured, {} lost",
            self.runs.len(),
            self.lost
        );
        for line in self.summary_lines() {
            println!("{line}");
        }
    }

    /// The chat phase's part of the report for `--write`.
    pub fn markdown(&self, setup: &str) -> String {
        format!(
            "### Open questions through the language model ({setup})\n\n{} runs measured, {} lost.\n\n```\n{}\n```\n",
            self.runs.len(),
            self.lost,
            self.summary_lines().join("\n")
        )
    }
}

/// `VmHWM` (peak resident set) of process `pid`, in kB, from `/proc/PID/status`.
pub fn peak_rss_kb(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|n| n.parse().ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_peak_resident_set_of_this_process_is_read() {
        let kb = peak_rss_kb(std::process::id());
        assert!(kb.is_some_and(|kb| kb > 0), "{kb:?}");
    }
}
