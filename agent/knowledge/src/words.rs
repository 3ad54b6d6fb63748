//! Words as the index sees them: the language's analyzer (split, lower case, stop words out, Snowball stem,
//! accents folded), shared by the passages and the questions so that "commands" finds "command".

use tantivy::tokenizer::{
    AsciiFoldingFilter, LowerCaser, RemoveLongFilter, SimpleTokenizer, Stemmer, StopWordFilter,
    TextAnalyzer, TokenStream,
};

/// The language of the folder and of the questions: which stemmer and stop words apply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Language {
    #[default]
    En,
    It,
}

impl Language {
    /// `"en"` / `"it"` (the agent's `[agent] language`), or `None` for another.
    pub fn from_code(code: &str) -> Option<Language> {
        match code.to_ascii_lowercase().as_str() {
            "en" | "english" => Some(Language::En),
            "it" | "italian" => Some(Language::It),
            _ => None,
        }
    }

    fn stop_words(self) -> &'static [&'static str] {
        match self {
            Language::En => ENGLISH_STOP,
            Language::It => ITALIAN_STOP,
        }
    }
}

/// The analyzer of `language`, for the index and for questions alike.
pub fn analyzer(language: Language) -> TextAnalyzer {
    let stemmer = match language {
        Language::En => tantivy::tokenizer::Language::English,
        Language::It => tantivy::tokenizer::Language::Italian,
    };
    TextAnalyzer::builder(SimpleTokenizer::default())
        .filter(RemoveLongFilter::limit(40))
        .filter(LowerCaser)
        .filter(StopWordFilter::remove(
            language.stop_words().iter().map(|w| (*w).to_string()),
        ))
        .filter(Stemmer::new(stemmer))
        // After the stemmer, which knows the accented forms: "perché" and a transcript's "perche" meet.
        .filter(AsciiFoldingFilter)
        .build()
}

/// The terms of `text`, in order, repeats kept.
pub fn terms(analyzer: &mut TextAnalyzer, text: &str) -> Vec<String> {
    let mut stream = analyzer.token_stream(text);
    let mut out = Vec::new();
    while stream.advance() {
        out.push(stream.token().text.clone());
    }
    out
}

/// The distinct terms of `text`, in first-seen order.
pub fn distinct_terms(analyzer: &mut TextAnalyzer, text: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for term in terms(analyzer, text) {
        if !out.contains(&term) {
            out.push(term);
        }
    }
    out
}

// The stop words say nothing about what a question is about: function words, pronouns, the question words and
// the fillers and frame verbs of a spoken request ("tell me", "please", "how do I make it...", "what happens
// when..."). They are left out of the index and of questions, so a question's remaining terms are its content,
// which the confidence rule counts. "can" stays: "what can you do" has nothing else.
const ENGLISH_STOP: &[&str] = &[
    "a",
    "about",
    "above",
    "after",
    "again",
    "against",
    "all",
    "also",
    "am",
    "an",
    "and",
    "any",
    "are",
    "aren",
    "as",
    "at",
    "be",
    "been",
    "before",
    "being",
    "below",
    "between",
    "both",
    "but",
    "by",
    "could",
    "couldn",
    "d",
    "did",
    "didn",
    "do",
    "does",
    "doesn",
    "doing",
    "don",
    "down",
    "during",
    "each",
    "else",
    "even",
    "ever",
    "every",
    "explain",
    "few",
    "for",
    "from",
    "further",
    "get",
    "gets",
    "had",
    "hadn",
    "happen",
    "happened",
    "happens",
    "has",
    "hasn",
    "have",
    "haven",
    "having",
    "he",
    "her",
    "here",
    "hers",
    "herself",
    "hey",
    "him",
    "himself",
    "his",
    "how",
    "i",
    "if",
    "in",
    "into",
    "is",
    "isn",
    "it",
    "its",
    "itself",
    "just",
    "know",
    "let",
    "ll",
    "m",
    "make",
    "makes",
    "may",
    "me",
    "might",
    "more",
    "most",
    "must",
    "my",
    "myself",
    "no",
    "nor",
    "not",
    "now",
    "of",
    "off",
    "oh",
    "ok",
    "okay",
    "on",
    "once",
    "only",
    "or",
    "other",
    "our",
    "ours",
    "ourselves",
    "out",
    "over",
    "please",
    "re",
    "really",
    "s",
    "same",
    "shall",
    "she",
    "should",
    "shouldn",
    "so",
    "some",
    "such",
    "t",
    "tell",
    "than",
    "that",
    "the",
    "their",
    "theirs",
    "them",
    "themselves",
    "then",
    "there",
    "these",
    "they",
    "this",
    "those",
    "through",
    "to",
    "too",
    "uh",
    "um",
    "under",
    "until",
    "up",
    "us",
    "ve",
    "very",
    "was",
    "wasn",
    "we",
    "well",
    "were",
    "weren",
    "what",
    "when",
    "where",
    "which",
    "while",
    "who",
    "whom",
    "whose",
    "why",
    "will",
    "with",
    "won",
    "would",
    "wouldn",
    "you",
    "your",
    "yours",
    "yourself",
    "yourselves",
];

const ITALIAN_STOP: &[&str] = &[
    "a", "abbiamo", "ad", "agli", "ai", "al", "all", "alla", "alle", "allo", "allora", "anche",
    "avete", "c", "che", "chi", "ci", "coi", "col", "come", "con", "cos", "cosa", "cui", "d", "da",
    "dagli", "dai", "dal", "dall", "dalla", "dalle", "dallo", "davvero", "degli", "dei", "del",
    "dell", "della", "delle", "dello", "di", "dimmi", "dimmelo", "dirmi", "dove", "e", "è", "ecco",
    "ed", "era", "erano", "ero", "essa", "esse", "essi", "esso", "favore", "fra", "gli", "gia",
    "già", "ha", "hai", "hanno", "ho", "i", "il", "in", "io", "l", "la", "le", "lei", "lo", "loro",
    "lui", "m", "ma", "me", "mi", "mia", "mie", "miei", "mio", "ne", "né", "nei", "negli", "nel",
    "nell", "nella", "nelle", "nello", "noi", "non", "nostra", "nostre", "nostri", "nostro", "o",
    "od", "per", "perche", "perché", "piu", "più", "poi", "potresti", "proprio", "puoi", "qual",
    "quale", "quali", "quando", "quanta", "quante", "quanti", "quanto", "quel", "quell", "quella",
    "quelle", "quelli", "quello", "quest", "questa", "queste", "questi", "questo", "s", "sai",
    "se", "sei", "si", "sia", "siamo", "siano", "siete", "sono", "spiega", "spiegami", "stata",
    "stato", "su", "sua", "sue", "sugli", "sui", "sul", "sull", "sulla", "sulle", "sullo", "suo",
    "suoi", "t", "te", "ti", "tra", "tu", "tua", "tue", "tuo", "tuoi", "un", "una", "uno", "v",
    "vi", "voglio", "voi", "vorrei", "vostra", "vostre", "vostri", "vostro",
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn english_terms_are_stemmed_and_stop_words_dropped() {
        let mut a = analyzer(Language::En);
        assert_eq!(
            terms(&mut a, "What are the Commands you understand?"),
            ["command", "understand"]
        );
        assert_eq!(terms(&mut a, "command"), terms(&mut a, "commands"));
    }

    #[test]
    fn italian_terms_are_stemmed_and_accents_folded() {
        let mut a = analyzer(Language::It);
        assert_eq!(
            terms(&mut a, "Che cosa sono le registrazioni?"),
            terms(&mut a, "registrazione")
        );
        assert_eq!(terms(&mut a, "perché città"), terms(&mut a, "citta"));
    }
}
