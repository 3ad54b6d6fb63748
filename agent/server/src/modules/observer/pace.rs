//! Whether the machine keeps up with the turn: each stage of the last turns against its budget, so that when the
//! configured models are too slow for the machine (or other work takes it) the log, `/metrics` and the page say
//! which stage is behind, instead of the agent only growing slow.
//!
//! A stage is behind when its median over the last [`WINDOW`] turns is over its budget, and keeps up again when the
//! median is back under 80% of it (so one turn either side of the line does not flap).

use std::collections::VecDeque;

use super::turns::TurnDone;

/// Turns the medians are taken over; a stage is judged from the third turn on.
pub const WINDOW: usize = 5;
const MIN_TURNS: usize = 3;

/// A turn's stages, in order.
pub const STAGES: [&str; 4] = ["vad", "transcription", "rule", "reply"];

/// `[modules.observer.budgets_ms]`: each stage's budget. The defaults are well over what a quiet 2-core machine takes
/// with the default models (docs/benchmarks.md, voice-latency: the silence hangover 300-700 ms, tiny.en's final
/// transcript 0-500 ms, a rule a few ms, a rule's reply 40-120 ms and the model's first sentence 450-900 ms), so that
/// only a machine that cannot keep up crosses them.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Budgets {
    pub vad: f64,
    pub transcription: f64,
    pub rule: f64,
    pub reply: f64,
}

impl Default for Budgets {
    fn default() -> Self {
        Budgets {
            vad: 1_000.0,
            transcription: 1_500.0,
            rule: 250.0,
            reply: 2_000.0,
        }
    }
}

impl Budgets {
    fn ms(&self) -> [f64; 4] {
        [self.vad, self.transcription, self.rule, self.reply]
    }

    /// Every budget a positive number of milliseconds; the error names the key.
    pub fn validate(&self) -> Result<(), String> {
        for (stage, ms) in STAGES.iter().zip(self.ms()) {
            if !(ms.is_finite() && ms > 0.0) {
                return Err(format!(
                    "budgets_ms.{stage}: {ms} is not a positive number of milliseconds"
                ));
            }
        }
        Ok(())
    }
}

/// A stage that fell behind or caught up with this turn.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    pub stage: &'static str,
    pub behind: bool,
    pub median_ms: f64,
    pub budget_ms: f64,
}

/// The last turns' stage times and which stages are behind.
#[derive(Debug, Default)]
pub struct Pace {
    budgets: Budgets,
    recent: [VecDeque<f64>; 4],
    behind: [bool; 4],
}

impl Pace {
    pub fn new(budgets: Budgets) -> Pace {
        Pace {
            budgets,
            ..Pace::default()
        }
    }

    /// Takes a finished turn; returns the stages whose state it changed.
    pub fn turn(&mut self, turn: &TurnDone) -> Vec<Change> {
        let ms = |us: u64| us as f64 / 1000.0;
        let times = [
            ms(turn.vad_us),
            ms(turn.transcript_us),
            ms(turn.rule_us),
            ms(turn.reply_us),
        ];
        let mut changes = Vec::new();
        for (i, t) in times.into_iter().enumerate() {
            let recent = &mut self.recent[i];
            recent.push_back(t);
            if recent.len() > WINDOW {
                recent.pop_front();
            }
            if recent.len() < MIN_TURNS {
                continue;
            }
            let median = median(recent);
            let (stage, budget) = (STAGES[i], self.budgets.ms()[i]);
            let behind = if self.behind[i] {
                median > 0.8 * budget
            } else {
                median > budget
            };
            if behind != self.behind[i] {
                self.behind[i] = behind;
                changes.push(Change {
                    stage,
                    behind,
                    median_ms: median,
                    budget_ms: budget,
                });
            }
        }
        changes
    }

    /// The stages behind now, in the turn's order.
    pub fn behind(&self) -> Vec<String> {
        STAGES
            .iter()
            .zip(self.behind)
            .filter(|(_, b)| *b)
            .map(|(stage, _)| (*stage).to_owned())
            .collect()
    }

    /// Whether `stage` (one of [`STAGES`]) is behind now.
    pub fn is_behind(&self, stage: &str) -> bool {
        STAGES
            .iter()
            .zip(self.behind)
            .any(|(s, b)| *s == stage && b)
    }
}

fn median(values: &VecDeque<f64>) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().collect();
    v.sort_by(f64::total_cmp);
    let mid = v.len() / 2;
    if v.len() % 2 == 1 {
        v[mid]
    } else {
        (v[mid - 1] + v[mid]) / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modules::observer::turns::TurnName;

    fn turn(transcript_ms: u64) -> TurnDone {
        TurnDone {
            name: TurnName {
                utterance: "u1".into(),
                trace: None,
                rule: "answer.time".into(),
            },
            speech_end_us: 0,
            vad_us: 400_000,
            transcript_us: transcript_ms * 1000,
            rule_us: 2_000,
            reply_us: 60_000,
            total_us: 462_000 + transcript_ms * 1000,
        }
    }

    #[test]
    fn a_slow_transcription_is_named_once_it_is_the_median_and_cleared_once_it_is_well_back() {
        let mut pace = Pace::default();
        for _ in 0..4 {
            assert!(pace.turn(&turn(300)).is_empty());
        }
        // One slow decode is not the machine: the median still keeps up.
        assert!(pace.turn(&turn(4_000)).is_empty());
        assert!(pace.turn(&turn(4_000)).is_empty());
        let changes = pace.turn(&turn(4_000));
        assert_eq!(changes.len(), 1, "{changes:?}");
        assert_eq!(changes[0].stage, "transcription");
        assert!(changes[0].behind && changes[0].median_ms > changes[0].budget_ms);
        assert_eq!(pace.behind(), vec!["transcription".to_owned()]);
        assert!(pace.is_behind("transcription") && !pace.is_behind("rule"));
        // Just under the budget is not yet back (no flapping at the line)...
        for _ in 0..5 {
            assert!(pace.turn(&turn(1_400)).is_empty());
        }
        // ...well under it is.
        let mut cleared = Vec::new();
        for _ in 0..5 {
            cleared.extend(pace.turn(&turn(300)));
        }
        assert_eq!(cleared.len(), 1, "{cleared:?}");
        assert!(!cleared[0].behind);
        assert!(pace.behind().is_empty());
    }

    #[test]
    fn a_budget_that_is_not_a_positive_number_is_refused_by_name() {
        let mut b = Budgets::default();
        assert!(b.validate().is_ok());
        b.rule = 0.0;
        assert!(b.validate().is_err_and(|e| e.contains("budgets_ms.rule")));
    }

    #[test]
    fn nothing_is_judged_before_the_third_turn() {
        let mut pace = Pace::default();
        assert!(pace.turn(&turn(9_000)).is_empty());
        assert!(pace.turn(&turn(9_000)).is_empty());
        assert_eq!(pace.turn(&turn(9_000)).len(), 1);
    }
}
