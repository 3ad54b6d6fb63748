//! The runs of one comparison (both sides, same requests) and the SUMMARY lines made of them: medians, ratios
//! and whether the targets are met.

use agent_bench::percentile;

use crate::wire::Reply;

/// The replies of both sides to the same requests, in order.
#[derive(Debug, Default)]
pub struct Runs {
    pub rust: Vec<Reply>,
    pub python: Vec<Reply>,
}

/// Medians of one side's runs.
struct Side {
    first_token_ms: f64,
    /// The fastest run: on a shared two-core machine the median carries other processes' load, the best less so.
    best_first_token_ms: f64,
    decode_tps: f64,
    best_decode_tps: f64,
    tokens: String,
    prompt_tokens: String,
    cached_tokens: Option<String>,
}

impl Side {
    fn of(replies: &[Reply]) -> Side {
        let ms: Vec<f64> = replies
            .iter()
            .filter_map(|r| r.first_token_s)
            .map(|s| s * 1000.0)
            .collect();
        let tps: Vec<f64> = replies.iter().filter_map(Reply::decode_tps).collect();
        let cached: Vec<f64> = replies
            .iter()
            .filter_map(|r| r.cached_tokens)
            .map(f64::from)
            .collect();
        Side {
            first_token_ms: percentile(&ms, 0.5),
            best_first_token_ms: percentile(&ms, 0.0),
            decode_tps: percentile(&tps, 0.5),
            best_decode_tps: percentile(&tps, 1.0),
            tokens: count(replies.iter().map(|r| Some(r.tokens))),
            prompt_tokens: count(replies.iter().map(|r| r.prompt_tokens)),
            cached_tokens: (!cached.is_empty()).then(|| format!("{:.0}", percentile(&cached, 0.5))),
        }
    }
}

/// The median of token counts, or the range when they differ between runs.
fn count(values: impl Iterator<Item = Option<u32>>) -> String {
    let mut v: Vec<u32> = values.flatten().collect();
    v.sort_unstable();
    match (v.first(), v.last()) {
        (Some(a), Some(b)) if a == b => a.to_string(),
        (Some(a), Some(b)) => format!("{a}-{b}"),
        _ => "?".into(),
    }
}

fn verdict(met: bool) -> &'static str {
    if met { "met" } else { "missed" }
}

impl Runs {
    /// How many runs got the same text from both sides (greedy decoding of the same file: the vendored llama.cpp
    /// versions differ, so the texts may part after a while).
    fn same_texts(&self) -> usize {
        self.rust
            .iter()
            .zip(&self.python)
            .filter(|(r, p)| r.text == p.text)
            .count()
    }

    /// `SUMMARY NAME: ...` for the time to first token, target Rust <= 1.0x Python.
    pub fn first_token_line(&self, name: &str, baseline: &str) -> String {
        let (rust, python) = (Side::of(&self.rust), Side::of(&self.python));
        let ratio = rust.first_token_ms / python.first_token_ms;
        let cached = rust
            .cached_tokens
            .map(|c| format!(", {c} from cache"))
            .unwrap_or_default();
        format!(
            "SUMMARY {name}: Rust llm-sat {:.1} ms median of {} runs (best {:.1}; {} prompt tokens{cached}), \
             {baseline} {:.1} ms (best {:.1}; {} prompt tokens); ratio of medians {ratio:.2} (target <= 1.0): {}",
            rust.first_token_ms,
            self.rust.len(),
            rust.best_first_token_ms,
            rust.prompt_tokens,
            python.first_token_ms,
            python.best_first_token_ms,
            python.prompt_tokens,
            verdict(ratio <= 1.0)
        )
    }

    /// `SUMMARY NAME: ...` for the decode pace, target Rust >= 1.0x Python.
    pub fn decode_line(&self, name: &str, baseline: &str) -> String {
        let (rust, python) = (Side::of(&self.rust), Side::of(&self.python));
        let ratio = rust.decode_tps / python.decode_tps;
        format!(
            "SUMMARY {name}: Rust llm-sat {:.1} tok/s median (best {:.1}; {} tokens per run), {baseline} {:.1} tok/s \
             (best {:.1}; {} tokens); ratio of medians {ratio:.2} (target >= 1.0): {}; same greedy text in {} of {} runs",
            rust.decode_tps,
            rust.best_decode_tps,
            rust.tokens,
            python.decode_tps,
            python.best_decode_tps,
            python.tokens,
            verdict(ratio >= 1.0),
            self.same_texts(),
            self.rust.len().min(self.python.len())
        )
    }
}

/// One run of both sides, for the log above the summary.
pub fn run_line(label: &str, run: usize, rust: &Reply, python: &Reply) -> String {
    let side = |r: &Reply| {
        format!(
            "first token {} ms, {} tok/s, {} tokens ({}), prompt {} tokens{}",
            r.first_token_s
                .map_or("-".into(), |s| format!("{:.1}", s * 1000.0)),
            r.decode_tps().map_or("-".into(), |t| format!("{t:.1}")),
            r.tokens,
            r.ended.as_deref().unwrap_or("?"),
            r.prompt_tokens.map_or("?".into(), |p| p.to_string()),
            r.cached_tokens
                .map(|c| format!(" ({c} cached)"))
                .unwrap_or_default()
        )
    };
    format!(
        "{label} run {}: rust {} | python {}",
        run + 1,
        side(rust),
        side(python)
    )
}
