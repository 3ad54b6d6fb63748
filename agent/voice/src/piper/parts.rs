//! Where the first sentence of a reply is cut so that its first part can be spoken while the rest is synthesised:
//! the first natural break (a clause's punctuation, or before a joining word) after a few words.
//!
//! The network speaks a whole input at once, so its first sample waits for the whole sentence: 300-500 ms for a
//! long one on this machine. A first part of three to eight words comes back in about a third of that, and the
//! rest is ready long before the first part has been heard.

/// Words that start a new phrase: a cut before them falls where a speaker may pause. Words that are as often
/// something else ("so" happy, "that" book, "before" noon) are left out.
const JOINING_WORDS: [&str; 15] = [
    "and", "but", "or", "because", "which", "who", "whom", "whose", "when", "while", "if", "where",
    "although", "unless", "whereas",
];

/// Fewest words a later part may have: a cut that leaves one or two words behind gains nothing.
const MIN_REST_WORDS: usize = 2;

/// Splits `sentence` at its first natural break after at least `min_words` words: after a word ending in `,`, `:`,
/// `;` or a dash, or before a joining word ("and", "because", "which"...). `None` when there is no such break
/// with at least two words after it, or when `min_words` is 0 (cutting switched off).
pub(crate) fn first_break(sentence: &str, min_words: usize) -> Option<(&str, &str)> {
    if min_words == 0 {
        return None;
    }
    let words: Vec<(usize, &str)> = word_starts(sentence);
    for position in min_words..words.len() {
        if words.len() - position < MIN_REST_WORDS {
            break;
        }
        let (_, before) = words[position - 1];
        let (start, word) = words[position];
        let after_clause = before.ends_with([',', ':', ';']) || matches!(before, "-" | "–" | "—");
        let bare = word
            .trim_matches(|c: char| !c.is_alphanumeric())
            .to_lowercase();
        if after_clause || JOINING_WORDS.contains(&bare.as_str()) {
            let head = sentence[..start].trim_end();
            let tail = sentence[start..].trim_start();
            return Some((head, tail));
        }
    }
    None
}

/// Every whitespace-separated word with its byte offset.
fn word_starts(text: &str) -> Vec<(usize, &str)> {
    let mut words = Vec::new();
    let mut start = None;
    for (index, c) in text.char_indices() {
        match (c.is_whitespace(), start) {
            (true, Some(from)) => {
                words.push((from, &text[from..index]));
                start = None;
            }
            (false, None) => start = Some(index),
            _ => {}
        }
    }
    if let Some(from) = start {
        words.push((from, &text[from..]));
    }
    words
}

#[cfg(test)]
mod tests {
    use super::first_break;

    #[test]
    fn a_clause_after_three_words_is_the_first_part() {
        assert_eq!(
            first_break("Good evening, nice to see you again today.", 2),
            Some(("Good evening,", "nice to see you again today."))
        );
        assert_eq!(
            first_break("I can tell you the time, or what I see in front of me.", 3),
            Some(("I can tell you the time,", "or what I see in front of me."))
        );
    }

    #[test]
    fn a_joining_word_is_a_break_when_no_clause_comes_first() {
        assert_eq!(
            first_break(
                "The sky looks blue because air scatters blue light the most.",
                3
            ),
            Some((
                "The sky looks blue",
                "because air scatters blue light the most."
            ))
        );
        // "And" at the start is not a break: fewer than three words come before it.
        assert_eq!(
            first_break("And then we went home and slept.", 3),
            Some(("And then we went home", "and slept."))
        );
    }

    #[test]
    fn short_sentences_and_sentences_without_a_break_stay_whole() {
        assert_eq!(first_break("Hello there!", 3), None);
        assert_eq!(
            first_break("It is a quarter past three in the afternoon.", 3),
            None
        );
        // A break that would leave one word behind is not taken.
        assert_eq!(first_break("I think you are right, sir.", 3), None);
        assert_eq!(first_break("Good evening, nice to see you.", 0), None);
    }

    #[test]
    fn the_parts_keep_every_character_but_the_space_between() {
        let sentence = "Well,   I am here, and I am listening to you.";
        let (head, tail) = first_break(sentence, 3).expect("a break");
        assert_eq!(
            (head, tail),
            ("Well,   I am here,", "and I am listening to you.")
        );
        assert_eq!(
            format!("{head} {tail}")
                .split_whitespace()
                .collect::<Vec<_>>(),
            sentence.split_whitespace().collect::<Vec<_>>()
        );
    }
}
