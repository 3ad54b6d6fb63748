//! Whether a transcript reads as a finished turn: the end-of-turn heuristic that lets a paused utterance end
//! after a short confirmation silence instead of the whole hangover, or hold on longer when the user is plainly
//! mid-sentence.
//!
//! The decision is made on the speculative transcript of a pause (see `speculation`), so it costs nothing beyond
//! the decode that was running anyway. It is a documented heuristic rather than a model (no turn-detection model
//! ships in a package registry for CPU; docs/asr.md):
//!
//! - **Incomplete** when the text trails off: it ends in an ellipsis, a comma, a dash or a colon; its last word is
//!   one a sentence cannot end on (a conjunction, an article, a preposition, a possessive, an auxiliary, a
//!   filler such as "um"); or it opens with a question word and has no verb to go with it ("What time?").
//! - **Complete** when it ends with `.`, `?` or `!` (Whisper punctuates what it hears as finished: "Turn left.",
//!   "Yes.") and none of the above holds; and, unpunctuated, when it is a **command**: it opens with a verb in the
//!   imperative from a list of the verbs people address to a robot or an assistant ("turn left", "stop", "look at
//!   me", "ask what you can do for your country") and none of the above holds. Whisper often leaves a short command
//!   unpunctuated ("turn left"), and an imperative that does not trail off is a whole turn.
//! - **Unknown** for anything else (an empty text, an unpunctuated stretch, which is how Whisper writes a fragment
//!   it is unsure of): the ordinary hangover decides.
//!
//! The word lists are English, the language of the default model; a text in another language is judged by its
//! punctuation alone.

/// What a transcript says about the end of the turn (the contract's type: transcripts carry it).
pub use agent_contract::transcript::TurnVerdict as Turn;

/// Words a sentence does not end on: conjunctions, articles, prepositions, possessives, auxiliaries, fillers.
const TRAILING: &[&str] = &[
    "and", "or", "but", "so", "because", "if", "then", "than", "that", "which", "who", "whose",
    "when", "while", "where", "although", "though", "unless", "until", "the", "a", "an", "this",
    "these", "those", "my", "your", "his", "her", "its", "our", "their", "to", "of", "for", "with",
    "at", "by", "from", "in", "into", "on", "onto", "about", "as", "like", "is", "are", "was",
    "were", "am", "be", "been", "can", "could", "will", "would", "should", "shall", "may", "might",
    "must", "do", "does", "did", "have", "has", "had", "not", "very", "um", "uh", "er", "erm",
    "hmm", "mm", "ah", "eh",
];

/// Words that open a question which needs a verb to be whole.
const QUESTION: &[&str] = &[
    "what", "where", "when", "who", "whom", "whose", "why", "how", "which",
];

/// Verbs and auxiliaries that make a question-word opening whole ("what is ...", "how are you").
const QUESTION_VERBS: &[&str] = &[
    "is", "are", "was", "were", "am", "do", "does", "did", "can", "could", "will", "would",
    "should", "shall", "may", "might", "must", "have", "has", "had", "go", "goes", "went", "see",
    "say", "said", "mean", "know", "think", "want", "happen", "happened", "work", "works", "get",
    "make", "call", "called", "look", "looks", "feel", "like", "come", "came",
];

/// Verbs that open a command when they come first ("turn left", "stop"). Words that are as often nouns or openers of
/// longer statements ("like", "mind", "check") are left out: a command must read as one.
const COMMANDS: &[&str] = &[
    "turn",
    "stop",
    "go",
    "come",
    "look",
    "move",
    "show",
    "tell",
    "say",
    "read",
    "count",
    "wait",
    "start",
    "sit",
    "stand",
    "ask",
    "give",
    "bring",
    "take",
    "put",
    "open",
    "close",
    "follow",
    "listen",
    "watch",
    "repeat",
    "continue",
    "help",
    "answer",
    "describe",
    "find",
    "play",
    "pause",
    "speak",
    "smile",
    "nod",
    "blink",
    "greet",
    "introduce",
    "remember",
    "forget",
    "cancel",
    "quit",
    "halt",
    "hold",
    "raise",
    "lower",
    "walk",
    "run",
    "please",
];

/// Judges `text` (a transcript, annotations already stripped).
pub fn judge(text: &str) -> Turn {
    let text = text
        .trim()
        .trim_end_matches(['"', '\'', ')', ']', '\u{201d}', '\u{2019}']);
    if text.is_empty() {
        return Turn::Unknown;
    }
    if text.ends_with("...") || text.ends_with('\u{2026}') {
        return Turn::Incomplete;
    }
    if text.ends_with([',', ';', ':', '-', '\u{2013}', '\u{2014}']) {
        return Turn::Incomplete;
    }
    let words: Vec<String> = text
        .split_whitespace()
        .map(|w| {
            w.trim_matches(|c: char| !c.is_alphanumeric() && c != '\'')
                .to_lowercase()
        })
        .filter(|w| !w.is_empty())
        .collect();
    let Some(last) = words.last() else {
        return Turn::Unknown;
    };
    if TRAILING.contains(&last.as_str()) {
        return Turn::Incomplete;
    }
    if words
        .first()
        .is_some_and(|w| QUESTION.contains(&w.as_str()))
        && !has_verb(&words[1..])
    {
        return Turn::Incomplete;
    }
    if text.ends_with(['.', '?', '!']) || COMMANDS.contains(&words[0].as_str()) {
        Turn::Complete
    } else {
        Turn::Unknown
    }
}

/// True when `words` hold a verb a question can stand on, a contracted one included ("what's", "where're").
fn has_verb(words: &[String]) -> bool {
    words.iter().any(|w| {
        QUESTION_VERBS.contains(&w.as_str())
            || w.ends_with("'s")
            || w.ends_with("'re")
            || w.ends_with("'m")
            || w.ends_with("'ll")
            || w.ends_with("'d")
            || w.ends_with("'ve")
            || w.ends_with("ing")
            || w.ends_with("ed")
    }) || words.len() >= 3
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn questions_commands_and_sentences_read_complete() {
        for text in [
            "What time is it?",
            "What's your name?",
            "How are you?",
            "Turn left.",
            "Yes.",
            "Hello there!",
            "I would like a cup of tea.",
            " Where did you go? ",
            "\"Stop.\"",
        ] {
            assert_eq!(judge(text), Turn::Complete, "{text:?}");
        }
    }

    #[test]
    fn unpunctuated_commands_read_complete_unless_they_trail_off() {
        for text in [
            "turn left",
            "stop",
            "Look at me",
            "ask what you can do for your country",
            "please tell me the time",
        ] {
            assert_eq!(judge(text), Turn::Complete, "{text:?}");
        }
        for text in [
            "turn left and",
            "tell me about",
            "go to the",
            "show me your",
        ] {
            assert_eq!(judge(text), Turn::Incomplete, "{text:?}");
        }
    }

    #[test]
    fn texts_that_trail_off_read_incomplete() {
        for text in [
            "What time",
            "What time?",
            "What time...",
            "Where",
            "I want to",
            "Turn left and",
            "Could you tell me the",
            "So, um",
            "I went to the shop,",
            "The thing is:",
            "It was very",
            "How about the…",
        ] {
            assert_eq!(judge(text), Turn::Incomplete, "{text:?}");
        }
    }

    #[test]
    fn empty_or_long_unpunctuated_text_is_left_to_the_hangover() {
        for text in [
            "",
            "   ",
            "...!",
            "the quick brown fox jumps over lazy dogs",
            "in the comparative",
            "produced the block books",
        ] {
            assert_eq!(judge(text), Turn::Unknown, "{text:?}");
        }
    }
}
