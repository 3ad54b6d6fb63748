//! Word error rate against a reference transcript, after normalising case and punctuation.

/// Lower-cases, turns every character that is not a letter, digit or apostrophe into a space, drops apostrophes
/// (so "don't" and "dont" compare equal) and splits into words.
pub fn normalise(text: &str) -> Vec<String> {
    text.chars()
        .filter(|&c| c != '\'' && c != '’')
        .map(|c| if c.is_alphanumeric() { c } else { ' ' })
        .collect::<String>()
        .to_lowercase()
        .split_whitespace()
        .map(str::to_owned)
        .collect()
}

/// Word-level edit distance (substitutions + deletions + insertions) between normalised texts, and the number of
/// reference words.
pub fn word_errors(reference: &str, hypothesis: &str) -> (usize, usize) {
    let r = normalise(reference);
    let h = normalise(hypothesis);
    let mut prev: Vec<usize> = (0..=h.len()).collect();
    let mut cur = vec![0; h.len() + 1];
    for (i, rw) in r.iter().enumerate() {
        cur[0] = i + 1;
        for (j, hw) in h.iter().enumerate() {
            let sub = prev[j] + usize::from(rw != hw);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    (prev[h.len()], r.len())
}

/// Word error rate: errors / reference words (1.0 per error on an empty reference).
pub fn wer(reference: &str, hypothesis: &str) -> f64 {
    let (errors, words) = word_errors(reference, hypothesis);
    errors as f64 / words.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn punctuation_and_case_do_not_count() {
        assert_eq!(
            wer("And so, my fellow Americans.", "and so my fellow americans"),
            0.0
        );
        assert_eq!(normalise("Don't STOP—now!"), vec!["dont", "stop", "now"]);
    }

    #[test]
    fn counts_substitutions_insertions_and_deletions() {
        assert_eq!(word_errors("a b c d", "a x c d"), (1, 4));
        assert_eq!(word_errors("a b c d", "a b c d e"), (1, 4));
        assert_eq!(word_errors("a b c d", "b c"), (2, 4));
        assert_eq!(word_errors("a b", ""), (2, 2));
        assert!((wer("the birch canoe slid", "the bird canoe slid on") - 0.5).abs() < 1e-12);
    }
}
