//! The question sets about the example folder (`questions.toml`): how often the right passage is in the top 3, how
//! often best() gives the passage with the key fact, and how often it answers an off-topic question.

use agent_bench::knowledge_set::{Sets, has_fact};
use agent_knowledge::Knowledge;

/// The figures of one run over the sets.
#[derive(Debug, Default)]
pub struct Scores {
    pub on_topic: usize,
    /// The expected file's passage with the fact among the three best hits.
    pub in_top3: usize,
    /// best() gave a passage with the fact.
    pub best_fact: usize,
    /// best() gave nothing for an on-topic question.
    pub best_none: usize,
    pub off_topic: usize,
    /// best() gave a passage for an off-topic question.
    pub off_answered: usize,
    /// The coverage of each on-topic question whose candidate is the expected passage.
    pub right_coverages: Vec<f64>,
    /// The coverage of each off-topic question's candidate (none when nothing matched at all).
    pub off_coverages: Vec<f64>,
}

/// Runs every question, printing the misses.
pub fn score(knowledge: &Knowledge, sets: &Sets) -> Scores {
    let mut s = Scores {
        on_topic: sets.on_topic.len(),
        off_topic: sets.off_topic.len(),
        ..Scores::default()
    };
    for q in &sets.on_topic {
        let hits = knowledge.search(&q.question, 3);
        let found = hits
            .iter()
            .any(|h| h.file == q.file && has_fact(&h.text, &q.fact));
        if found {
            s.in_top3 += 1;
        } else {
            let got: Vec<String> = hits
                .iter()
                .map(|h| format!("{} [{}] {:.2}", h.file, h.heading, h.score))
                .collect();
            println!(
                "knowledge-bench: miss top 3: {:?} wants {} with {:?}; got {:?}",
                q.question, q.file, q.fact, got
            );
        }
        let candidate = knowledge.candidate(&q.question);
        if let Some(c) = &candidate {
            let right = c.hit.file == q.file && has_fact(&c.hit.text, &q.fact);
            if right {
                s.right_coverages.push(f64::from(c.coverage));
            }
            println!(
                "knowledge-bench: on-topic {:?}: candidate {} [{}] coverage {:.2}{}",
                q.question,
                c.hit.file,
                c.hit.heading,
                c.coverage,
                if right {
                    ""
                } else {
                    " (not the expected passage)"
                }
            );
        }
        match knowledge.best(&q.question) {
            Some(hit) if hit.file == q.file && has_fact(&hit.text, &q.fact) => s.best_fact += 1,
            Some(hit) => println!(
                "knowledge-bench: best() wrong passage: {:?} gave {} [{}]: {:?}",
                q.question, hit.file, hit.heading, hit.text
            ),
            None => {
                s.best_none += 1;
                println!("knowledge-bench: best() gave nothing: {:?}", q.question);
            }
        }
    }
    for q in &sets.off_topic {
        if let Some(c) = knowledge.candidate(q) {
            s.off_coverages.push(f64::from(c.coverage));
            println!(
                "knowledge-bench: off-topic {:?}: candidate {} [{}] coverage {:.2}",
                q, c.hit.file, c.hit.heading, c.coverage
            );
        }
        if let Some(hit) = knowledge.best(q) {
            s.off_answered += 1;
            println!(
                "knowledge-bench: best() answered off-topic {:?} with {} [{}]: {:?}",
                q, hit.file, hit.heading, hit.text
            );
        }
    }
    s
}
