//! The knowledge phase: the questions about the example folder (`bench/knowledge/questions.toml`) typed as final
//! transcripts, one at a time, to robot-agent on the shipped program with `knowledge/` and llm-sat beside it. For
//! each: the passage the brain used (its trace's `passage` step: said by a rule's `recall(T)` or quoted in the
//! model's facts) and the spoken answer (the recalled passage, or the model's sentences), checked for the question's
//! key fact.

use std::time::{Duration, Instant};

use agent_bench::knowledge_set::{OnTopic, has_fact};
use flow::Publisher;

use crate::watch::Watcher;

/// A recalled passage is said at once; a model's reply of three sentences fits well within this.
const ANSWER_PATIENCE: Duration = Duration::from_secs(60);
/// The issue's targets: the right passage in the facts, and the key fact in the spoken answer.
const PASSAGE_TARGET: f64 = 0.90;
const FACT_TARGET: f64 = 0.70;

/// Everything the phase measured.
#[derive(Debug, Default)]
pub struct KnowledgeFigures {
    pub questions: usize,
    /// A passage of the expected file holding the key fact was recalled or put in the model's facts.
    pub right_passage: usize,
    /// Answered by a rule's `recall(T)`, and of them with the key fact.
    pub recalled: usize,
    pub recalled_fact: usize,
    /// Handed to the model, and of them with the key fact in its spoken reply.
    pub by_model: usize,
    pub by_model_fact: usize,
    /// The key fact in the spoken answer, whoever gave it.
    pub fact_spoken: usize,
    pub lost: usize,
}

/// Types each question and follows its answer; the next is typed once the agent has finished speaking.
pub async fn measure(
    watcher: &mut Watcher,
    transcript: &Publisher,
    questions: &[OnTopic],
) -> anyhow::Result<KnowledgeFigures> {
    let mut figures = KnowledgeFigures {
        questions: questions.len(),
        ..KnowledgeFigures::default()
    };
    for (i, q) in questions.iter().enumerate() {
        let message = serde_json::json!({ "text": q.question, "final": true }).to_string();
        transcript.publish(message.into_bytes()).await?;
        let answer = match watcher
            .follow_answer(&q.question, Instant::now() + ANSWER_PATIENCE)
            .await
        {
            Ok(answer) => answer,
            Err(e) => {
                println!("  knowledge {:>2} {:?} lost: {e:#}", i + 1, q.question);
                figures.lost += 1;
                watcher.until_quiet(Duration::from_millis(800)).await?;
                continue;
            }
        };
        let right = answer.passages.iter().any(|p| {
            (p.starts_with(&format!("{}:", q.file)) || p.starts_with(&format!("{} (", q.file)))
                && has_fact(p, &q.fact)
        });
        let fact = has_fact(&answer.spoken, &q.fact);
        figures.right_passage += usize::from(right);
        figures.fact_spoken += usize::from(fact);
        if answer.recalled() {
            figures.recalled += 1;
            figures.recalled_fact += usize::from(fact);
        } else if answer.by_model() {
            figures.by_model += 1;
            figures.by_model_fact += usize::from(fact);
        }
        println!(
            "  knowledge {:>2} {:<7} passage {:<5} fact {:<5} {:?} -> {:?} (expected {} with {:?}; passages {:?})",
            i + 1,
            if answer.recalled() {
                "recall"
            } else if answer.by_model() {
                "model"
            } else {
                "rule"
            },
            if right { "right" } else { "wrong" },
            if fact { "said" } else { "not" },
            q.question,
            answer.spoken,
            q.file,
            q.fact,
            answer
                .passages
                .iter()
                .map(|p| p.split(':').next().unwrap_or_default())
                .collect::<Vec<_>>()
        );
        // Let the answer play out, so the next question does not barge in on it.
        watcher.until_quiet(Duration::from_millis(800)).await?;
    }
    Ok(figures)
}

impl KnowledgeFigures {
    pub fn summary_lines(&self) -> Vec<String> {
        let share = |n: usize, of: usize| n as f64 / of.max(1) as f64;
        let met = |v: f64, target: f64| if v >= target { "met" } else { "missed" };
        let passage = share(self.right_passage, self.questions);
        let fact = share(self.fact_spoken, self.questions);
        vec![
            format!(
                "SUMMARY knowledge_right_passage: {:.0}% ({} of {} questions about the example folder had the expected file's passage with the key fact recalled or in the model's facts, {} lost; target >= {:.0}%: {})",
                100.0 * passage,
                self.right_passage,
                self.questions,
                self.lost,
                100.0 * PASSAGE_TARGET,
                met(passage, PASSAGE_TARGET)
            ),
            format!(
                "SUMMARY knowledge_fact_spoken: {:.0}% ({} of {} spoken answers hold the key fact: {} of {} recalled by the rule, {} of {} from the default model; target >= {:.0}%: {})",
                100.0 * fact,
                self.fact_spoken,
                self.questions,
                self.recalled_fact,
                self.recalled,
                self.by_model_fact,
                self.by_model,
                100.0 * FACT_TARGET,
                met(fact, FACT_TARGET)
            ),
        ]
    }

    pub fn print(&self) {
        println!();
        println!(
            "knowledge phase: {} questions about knowledge/ typed to the shipped program with llm-sat",
            self.questions
        );
        for line in self.summary_lines() {
            println!("{line}");
        }
    }

    pub fn markdown(&self) -> String {
        format!(
            "### Questions about the knowledge folder\n\n{} questions typed, {} lost.\n\n```\n{}\n```\n",
            self.questions,
            self.lost,
            self.summary_lines().join("\n")
        )
    }
}
