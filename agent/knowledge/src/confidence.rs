//! When a passage may be spoken as the answer by a rule, with no language model: the share of the question's
//! content, weighted by how much each term says, that the passage covers.
//!
//! A question's terms are its words less the stop words (`words.rs`), stemmed. Each is weighted by its inverse
//! document frequency over the folder's passages, so a word that every passage has ("agent") weighs little and a
//! word that no passage has ("joke", "France") weighs the most. A passage covers a term when its heading path,
//! file name or text has it. The coverage is the covered weight over the question's weight; a passage is
//! confident at [`MIN_COVERAGE`] or more. An off-topic question ("what is the capital of France?") has its
//! subject words in no passage, so even a passage that shares its other words stays far below the bar; an
//! on-topic one has its subject words in the passage about it. The bar is calibrated on the question sets of
//! `bench/knowledge/questions.toml` (docs/knowledge.md, "The confidence rule").

use std::collections::HashSet;

/// The least coverage of a confident passage.
pub const MIN_COVERAGE: f32 = 0.6;

/// The fewest of the question's terms a confident passage has: one shared word ("who made you?" and a passage on
/// how the agent's speech is made) is too thin a match to be said as the answer.
pub const MIN_MATCHED: usize = 2;

/// How many of the best-scored passages [`crate::Knowledge::best`] weighs: BM25 may put a long passage that
/// repeats one term above a short one that has all of them.
pub const CANDIDATES: usize = 3;

/// A term of the question with its weight.
#[derive(Debug, Clone, PartialEq)]
pub struct Weighted {
    pub term: String,
    pub weight: f32,
}

/// The share (0 to 1) of the question's weight whose terms `passage` has; 0 for a question without terms.
pub fn coverage(question: &[Weighted], passage: &HashSet<String>) -> f32 {
    let total: f32 = question.iter().map(|w| w.weight).sum();
    if total <= 0.0 {
        return 0.0;
    }
    let covered: f32 = question
        .iter()
        .filter(|w| passage.contains(&w.term))
        .map(|w| w.weight)
        .sum();
    covered / total
}

/// Whether a passage with this coverage, having `matched` of the question's terms, may answer alone.
pub fn is_confident(coverage: f32, matched: usize) -> bool {
    coverage >= MIN_COVERAGE && matched >= MIN_MATCHED
}

#[cfg(test)]
mod tests {
    use super::*;

    fn weighted(terms: &[(&str, f32)]) -> Vec<Weighted> {
        terms
            .iter()
            .map(|(t, w)| Weighted {
                term: (*t).to_string(),
                weight: *w,
            })
            .collect()
    }

    fn set(terms: &[&str]) -> HashSet<String> {
        terms.iter().map(|t| (*t).to_string()).collect()
    }

    #[test]
    fn a_passage_with_every_term_covers_the_whole_question() {
        let q = weighted(&[("privaci", 2.0), ("store", 1.5)]);
        assert_eq!(coverage(&q, &set(&["privaci", "store", "audio"])), 1.0);
        assert!(is_confident(1.0, 2));
        assert!(!is_confident(1.0, 1), "one shared word is too thin");
    }

    #[test]
    fn a_rare_term_the_passage_lacks_outweighs_a_common_one_it_has() {
        // "tell me a joke about the agent": "agent" is everywhere, "joke" nowhere.
        let q = weighted(&[("agent", 0.3), ("joke", 4.0)]);
        let c = coverage(&q, &set(&["agent", "whisper"]));
        assert!(c < 0.1, "{c}");
        assert!(!is_confident(c, 1));
    }

    #[test]
    fn a_question_without_content_terms_covers_nothing() {
        assert_eq!(coverage(&[], &set(&["agent"])), 0.0);
    }
}
