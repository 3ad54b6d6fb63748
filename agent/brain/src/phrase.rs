//! Forgiving matching of recognised speech: normalisation of ASR text, the `~` phrase patterns, and the echo score
//! the host uses to drop transcripts of the agent's own voice.

/// Contractions expanded before matching, so "what's the time" and "what is the time" read the same.
const CONTRACTIONS: [(&str, &str); 24] = [
    ("what's", "what is"),
    ("whats", "what is"),
    ("it's", "it is"),
    ("that's", "that is"),
    ("there's", "there is"),
    ("where's", "where is"),
    ("who's", "who is"),
    ("how's", "how is"),
    ("let's", "let us"),
    ("i'm", "i am"),
    ("you're", "you are"),
    ("we're", "we are"),
    ("they're", "they are"),
    ("i've", "i have"),
    ("you've", "you have"),
    ("i'll", "i will"),
    ("you'll", "you will"),
    ("i'd", "i would"),
    ("don't", "do not"),
    ("doesn't", "does not"),
    ("didn't", "did not"),
    ("can't", "can not"),
    ("cannot", "can not"),
    ("won't", "will not"),
];

/// Number words written as digits, since recognisers write "3" or "three" as they please (and the agent's own
/// sentences, spoken from digits, come back either way).
const NUMBERS: [(&str, &str); 28] = [
    ("zero", "0"),
    ("one", "1"),
    ("two", "2"),
    ("three", "3"),
    ("four", "4"),
    ("five", "5"),
    ("six", "6"),
    ("seven", "7"),
    ("eight", "8"),
    ("nine", "9"),
    ("ten", "10"),
    ("eleven", "11"),
    ("twelve", "12"),
    ("thirteen", "13"),
    ("fourteen", "14"),
    ("fifteen", "15"),
    ("sixteen", "16"),
    ("seventeen", "17"),
    ("eighteen", "18"),
    ("nineteen", "19"),
    ("twenty", "20"),
    ("thirty", "30"),
    ("forty", "40"),
    ("fifty", "50"),
    ("sixty", "60"),
    ("seventy", "70"),
    ("eighty", "80"),
    ("ninety", "90"),
];

/// Splits recognised text into lower-case words: drops bracketed annotations such as Whisper's `[BLANK_AUDIO]` or
/// `(music)`, turns punctuation into spaces, unifies apostrophes, expands common contractions and writes number
/// words as digits.
pub fn normalise(text: &str) -> Vec<String> {
    let mut cleaned = String::with_capacity(text.len());
    let mut depth = 0usize;
    for c in text.chars() {
        match c {
            '[' | '(' | '<' => depth += 1,
            ']' | ')' | '>' => depth = depth.saturating_sub(1),
            _ if depth > 0 => {}
            '\u{2019}' | '\u{2018}' | '`' => cleaned.push('\''),
            c if c.is_alphanumeric() || c == '\'' => cleaned.extend(c.to_lowercase()),
            _ => cleaned.push(' '),
        }
    }
    let mut words = Vec::new();
    for word in cleaned.split_whitespace() {
        let word = word.trim_matches('\'');
        if word.is_empty() {
            continue;
        }
        if let Some((_, long)) = CONTRACTIONS.iter().find(|(short, _)| *short == word) {
            words.extend(long.split(' ').map(str::to_owned));
        } else if let Some((_, digits)) = NUMBERS.iter().find(|(name, _)| *name == word) {
            words.push((*digits).to_owned());
        } else {
            words.push(word.to_owned());
        }
    }
    words
}

/// Whether two words are the same allowing for small recognition slips: exact for short words, one edit from five
/// letters, two edits from eight letters.
pub fn same_word(a: &str, b: &str) -> bool {
    if a == b {
        return true;
    }
    let shorter = a.chars().count().min(b.chars().count());
    let allowed = match shorter {
        0..=4 => 0,
        5..=7 => 1,
        _ => 2,
    };
    allowed > 0 && edit_distance(a, b) <= allowed
}

fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let mut previous: Vec<usize> = (0..=b.len()).collect();
    let mut current = vec![0; b.len() + 1];
    for (i, ca) in a.iter().enumerate() {
        current[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let substitution = previous[j] + usize::from(ca != cb);
            current[j + 1] = substitution.min(previous[j + 1] + 1).min(current[j] + 1);
        }
        std::mem::swap(&mut previous, &mut current);
    }
    previous[b.len()]
}

/// A compiled `~` pattern: words, `*` for any run of words, optional `^`/`$` anchors.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pattern {
    words: Vec<PatternWord>,
    anchored_start: bool,
    anchored_end: bool,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum PatternWord {
    Word(String),
    Any,
}

impl Pattern {
    /// Compiles a pattern such as `"read * code"` or `"^stop$"`; its words are normalised like speech.
    pub fn new(pattern: &str) -> Pattern {
        let trimmed = pattern.trim();
        let anchored_start = trimmed.starts_with('^');
        let anchored_end = trimmed.ends_with('$');
        let body = trimmed.trim_start_matches('^').trim_end_matches('$');
        let mut words = Vec::new();
        for (i, piece) in body.split('*').enumerate() {
            if i > 0 && words.last() != Some(&PatternWord::Any) {
                words.push(PatternWord::Any);
            }
            words.extend(normalise(piece).into_iter().map(PatternWord::Word));
        }
        Pattern {
            words,
            anchored_start,
            anchored_end,
        }
    }

    /// Whether the pattern occurs in the (already normalised) utterance.
    pub fn matches_words(&self, utterance: &[String]) -> bool {
        if self.words.is_empty() && !self.anchored_start && !self.anchored_end {
            // An empty pattern would match everything; it is almost certainly a mistake, so it matches nothing.
            return false;
        }
        let last_start = if self.anchored_start {
            0
        } else {
            utterance.len()
        };
        (0..=last_start).any(|start| self.matches_from(0, &utterance[start..]))
    }

    fn matches_from(&self, index: usize, rest: &[String]) -> bool {
        let Some(word) = self.words.get(index) else {
            return !self.anchored_end || rest.is_empty();
        };
        match word {
            PatternWord::Any => {
                (0..=rest.len()).any(|skip| self.matches_from(index + 1, &rest[skip..]))
            }
            PatternWord::Word(expected) => {
                rest.first().is_some_and(|heard| same_word(heard, expected))
                    && self.matches_from(index + 1, &rest[1..])
            }
        }
    }
}

/// The words of `text` after the first place the words of `phrase` occur in it (both normalised, words compared as
/// in [`Pattern`]), joined by spaces; `None` when the phrase is not there or nothing follows it.
/// `after("Hi, my name is Anna.", "my name is")` is `"anna"`.
pub fn after(text: &str, phrase: &str) -> Option<String> {
    let words = normalise(text);
    let wanted = normalise(phrase);
    if wanted.is_empty() {
        return None;
    }
    let start = (0..words.len().saturating_sub(wanted.len() - 1)).find(|&start| {
        wanted
            .iter()
            .zip(&words[start..])
            .all(|(w, heard)| same_word(heard, w))
    })?;
    let rest = &words[start + wanted.len()..];
    (!rest.is_empty()).then(|| rest.join(" "))
}

/// Whether `text` contains the phrase `pattern` (both normalised; see [`Pattern`]).
pub fn matches(text: &str, pattern: &str) -> bool {
    Pattern::new(pattern).matches_words(&normalise(text))
}

/// How much of a transcript is an echo of something the agent said: the share of the transcript's words that
/// appear, in order, in `said` (a fuzzy longest common subsequence), from 0.0 to 1.0.
///
/// The host drops a transcript whose score against a recent utterance is high: the microphone picked up the
/// agent's own voice. Recognition of synthetic speech is partial and noisy, hence in-order and fuzzy.
pub fn echo_score(transcript: &str, said: &str) -> f64 {
    let heard = normalise(transcript);
    if heard.is_empty() {
        return 0.0;
    }
    common_words(&heard, &normalise(said)) as f64 / heard.len() as f64
}

/// How many words two normalised texts share in order, allowing small slips (a longest common subsequence).
pub fn common_words(heard: &[String], said: &[String]) -> usize {
    if heard.is_empty() || said.is_empty() {
        return 0;
    }
    let mut previous = vec![0usize; said.len() + 1];
    let mut current = vec![0usize; said.len() + 1];
    for h in heard {
        for (j, s) in said.iter().enumerate() {
            current[j + 1] = if same_word(h, s) {
                previous[j] + 1
            } else {
                previous[j + 1].max(current[j])
            };
        }
        std::mem::swap(&mut previous, &mut current);
    }
    previous[said.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalises_asr_text() {
        assert_eq!(normalise("What's the time?"), ["what", "is", "the", "time"]);
        assert_eq!(
            normalise(" [BLANK_AUDIO] Hello, (music) WORLD!"),
            ["hello", "world"]
        );
        assert_eq!(
            normalise("I don\u{2019}t know."),
            ["i", "do", "not", "know"]
        );
        assert_eq!(
            normalise("Two people, 3 cats"),
            ["2", "people", "3", "cats"]
        );
    }

    #[test]
    fn phrase_patterns() {
        assert!(matches("What time is it?", "what time"));
        assert!(matches("what's the time", "the time"));
        assert!(!matches("what is the weather", "what time"));
        assert!(matches("Could you read this QR code please", "read * code"));
        assert!(matches("read code", "read * code"));
        assert!(matches("Stop.", "^stop$"));
        assert!(!matches("don't stop now", "^stop$"));
        assert!(!matches("stop it now", "stop$"));
    }

    #[test]
    fn tolerates_small_recognition_slips() {
        assert!(matches("how many peeple do you see", "how many people"));
        assert!(!matches("shop", "stop"));
        assert!(same_word("repeat", "repeet"));
        assert!(!same_word("time", "tame"));
    }

    #[test]
    fn echo_score_measures_overlap() {
        assert!(
            echo_score(
                "it is quarter past three",
                "It is quarter past 3 in the afternoon."
            ) > 0.7
        );
        assert!(echo_score("what time is it", "It is quarter past 3 in the afternoon.") < 0.5);
        assert_eq!(echo_score("", "anything"), 0.0);
    }
}
