//! Turns a model's streamed text into sentences fit to be spoken: where a sentence ends while tokens still arrive
//! (`Sentences`), and what a TTS should read of it (`speakable`: no markdown, no emoji, symbols and units in words).

/// A sentence without punctuation is cut at the first space after this many characters, so that speech can start.
const SOFT_LIMIT: usize = 200;
/// Text without any space is cut here (a run-away token stream must not grow the buffer without end).
const HARD_LIMIT: usize = 400;
/// The reply's first sentence is cut at its first natural break once it has this many words: the first audio then
/// starts while the rest of that sentence is generated. Later sentences wait for their end. A break is a clause's
/// punctuation (`,` `;` `:` and whitespace, not a comma before a number: "5 December, 2026") or the space before a
/// word that opens a clause ("because", "but", "which"...).
const FIRST_CLAUSE_WORDS: usize = 3;
/// Characters that end a clause.
const CLAUSE_ENDS: [char; 3] = [',', ';', ':'];
/// Words that open a clause: the first sentence may be cut before them ("The sky is blue | because air scatters
/// light"). Not "and", "or", "that", "to": they join words as often as clauses ("red and blue").
const CLAUSE_OPENERS: [&str; 17] = [
    "because", "but", "although", "though", "while", "which", "whereas", "unless", "however",
    "perché", "poiché", "ma", "però", "mentre", "quindi", "sebbene", "benché",
];
/// Characters that end a sentence when whitespace follows them.
const TERMINALS: [char; 4] = ['.', '!', '?', '…'];
/// Characters that may close a sentence after its terminal: `"Yes."` and `**Done.**` end where the closer does.
const CLOSERS: [char; 11] = ['"', '\'', ')', ']', '}', '”', '’', '»', '*', '_', '`'];
/// Words whose dot never ends a sentence (a name or an example follows them).
const NEVER_END: [&str; 13] = [
    "mr.", "mrs.", "ms.", "dr.", "st.", "prof.", "sig.", "dott.", "e.g.", "i.e.", "vs.", "es.",
    "p.es.",
];
/// Words whose dot ends a sentence only when no lowercase word follows (`etc. and` goes on, `etc. Then` does not);
/// dotted acronyms (`p.m.`, `U.S.`) are read the same way.
const MAYBE_END: [&str; 2] = ["etc.", "ecc."];

/// A streaming splitter: pieces of a reply in (token by token, a piece may be part of a word), sentences out in
/// spoken form as soon as the character after their end is known.
#[derive(Debug, Clone)]
pub struct Sentences {
    /// Text not yet handed out, from the start of the sentence being written.
    pending: Vec<char>,
    /// Inside a fenced code block (```), whose lines are never spoken.
    in_fence: bool,
    language: String,
    max_sentences: u32,
    count: u32,
    capped: bool,
    /// A piece was handed out already (the first clause or sentence).
    started: bool,
}

/// Where the pending text is cut.
enum Cut {
    /// The sentence (or, for the first, a clause of it) is `pending[..end]`; the next one starts at `resume`.
    At {
        end: usize,
        resume: usize,
        clause: bool,
    },
    /// No end is known yet.
    Wait,
}

/// Whether a terminal at some position ends a sentence.
enum Verdict {
    /// It does; the sentence ends before this index (after any closers).
    End(usize),
    NotEnd,
    /// The characters that decide have not arrived yet.
    Unknown,
}

impl Sentences {
    /// A splitter that hands out at most `max_sentences` sentences (0: no limit), in English until
    /// [`Sentences::in_language`] says otherwise.
    pub fn new(max_sentences: u32) -> Self {
        Sentences {
            pending: Vec::new(),
            in_fence: false,
            language: "en".to_owned(),
            max_sentences,
            count: 0,
            capped: false,
            started: false,
        }
    }

    /// The language the sentences are spoken in (`en`, `it`): it decides how symbols and units are read.
    pub fn in_language(mut self, language: &str) -> Self {
        language.clone_into(&mut self.language);
        self
    }

    /// Takes the next piece of the reply; returns the sentences it completed, in spoken form (empty ones skipped).
    pub fn push(&mut self, piece: &str) -> Vec<String> {
        let mut done = Vec::new();
        if self.capped {
            return done;
        }
        self.pending.extend(piece.chars());
        loop {
            self.trim_start();
            match self.next_cut() {
                Cut::Wait => break,
                Cut::At {
                    end,
                    resume,
                    clause,
                } => {
                    let raw: String = self.pending[..end].iter().collect();
                    self.pending.drain(..resume);
                    self.hand_out(&raw, clause, &mut done);
                    if self.capped {
                        break;
                    }
                }
            }
        }
        done
    }

    /// The reply ended: the rest of the text as its last sentence, if anything of it is to be spoken.
    pub fn finish(&mut self) -> Option<String> {
        if self.capped {
            return None;
        }
        let raw: String = self.pending.drain(..).collect();
        let mut done = Vec::new();
        self.hand_out(&raw, false, &mut done);
        self.in_fence = false;
        done.pop()
    }

    /// Sentences handed out so far.
    pub fn count(&self) -> u32 {
        self.count
    }

    /// The limit of sentences was reached: later pieces are dropped.
    pub fn capped(&self) -> bool {
        self.capped
    }

    fn trim_start(&mut self) {
        let blank = self
            .pending
            .iter()
            .take_while(|c| c.is_whitespace())
            .count();
        self.pending.drain(..blank);
    }

    /// The first place the pending text ends a sentence, deciding in order so that the same text gives the same
    /// sentences however it was split into pieces.
    fn next_cut(&self) -> Cut {
        for (i, &c) in self.pending.iter().enumerate() {
            if i >= HARD_LIMIT {
                return Cut::At {
                    end: i,
                    resume: i,
                    clause: false,
                };
            }
            if c == '\n' {
                return Cut::At {
                    end: i,
                    resume: i + 1,
                    clause: false,
                };
            }
            if self.in_fence {
                continue;
            }
            if TERMINALS.contains(&c) {
                match self.verdict(i) {
                    Verdict::End(end) => {
                        return Cut::At {
                            end,
                            resume: end,
                            clause: false,
                        };
                    }
                    Verdict::Unknown => return Cut::Wait,
                    Verdict::NotEnd => {}
                }
            }
            if !self.started {
                match self.clause_break(i) {
                    Some(Some((end, resume))) => {
                        return Cut::At {
                            end,
                            resume,
                            clause: true,
                        };
                    }
                    None => return Cut::Wait,
                    Some(None) => {}
                }
            }
            if c.is_whitespace() && i >= SOFT_LIMIT {
                return Cut::At {
                    end: i,
                    resume: i,
                    clause: false,
                };
            }
        }
        Cut::Wait
    }

    /// Whether the first sentence may be cut at `at`: `Some(Some((end, resume)))` where it is cut, `Some(None)` if
    /// not there, `None` while the characters that decide have not arrived.
    fn clause_break(&self, at: usize) -> Option<Option<(usize, usize)>> {
        let cs = &self.pending;
        let c = cs[at];
        if CLAUSE_ENDS.contains(&c) {
            let after = *cs.get(at + 1)?;
            if !after.is_whitespace() || words(&cs[..at]) < FIRST_CLAUSE_WORDS {
                return Some(None);
            }
            // "5 December, 2026", "1, 2, 3": a number after the comma belongs with what came before.
            let next = *cs[at + 1..].iter().find(|c| !c.is_whitespace())?;
            if c == ',' && next.is_ascii_digit() {
                return Some(None);
            }
            return Some(Some((at + 1, at + 1)));
        }
        if !c.is_whitespace() || cs.get(at + 1).is_some_and(|c| c.is_whitespace()) {
            return Some(None);
        }
        // The space before a word: is the word one that opens a clause?
        let rest = &cs[at + 1..];
        let length = rest.iter().take_while(|c| c.is_alphabetic()).count();
        let word: String = rest[..length]
            .iter()
            .flat_map(|c| c.to_lowercase())
            .collect();
        if length == rest.len() {
            // The word may still grow: wait only if it could become an opener.
            let could = !word.is_empty() && CLAUSE_OPENERS.iter().any(|o| o.starts_with(&word));
            return if could { None } else { Some(None) };
        }
        let closed = rest[length].is_whitespace() || rest[length] == ',';
        if closed
            && CLAUSE_OPENERS.contains(&word.as_str())
            && words(&cs[..at]) >= FIRST_CLAUSE_WORDS
        {
            return Some(Some((at, at + 1)));
        }
        Some(None)
    }

    fn verdict(&self, at: usize) -> Verdict {
        let cs = &self.pending;
        let mut end = at + 1;
        while end < cs.len() && CLOSERS.contains(&cs[end]) {
            end += 1;
        }
        let Some(&after) = cs.get(end) else {
            return Verdict::Unknown;
        };
        if !after.is_whitespace() {
            // "3.5", "e.g", "?!": the end, if any, is further on.
            return Verdict::NotEnd;
        }
        if cs[at] != '.' {
            return Verdict::End(end);
        }
        let start = cs[..at]
            .iter()
            .rposition(|c| c.is_whitespace())
            .map_or(0, |p| p + 1);
        let word: String = cs[start..=at]
            .iter()
            .skip_while(|c| matches!(c, '(' | '[' | '"' | '\'' | '“' | '‘' | '«' | '*' | '_'))
            .flat_map(|c| c.to_lowercase())
            .collect();
        if NEVER_END.contains(&word.as_str()) {
            return Verdict::NotEnd;
        }
        if MAYBE_END.contains(&word.as_str()) || is_dotted_acronym(&word) {
            return match cs[end..].iter().find(|c| !c.is_whitespace()) {
                None => Verdict::Unknown,
                Some(next) if next.is_lowercase() => Verdict::NotEnd,
                Some(_) => Verdict::End(end),
            };
        }
        let number = &cs[start..at];
        let list_marker = !number.is_empty()
            && number.iter().all(char::is_ascii_digit)
            && cs[..start].iter().all(|c| c.is_whitespace());
        if list_marker {
            return Verdict::NotEnd;
        }
        Verdict::End(end)
    }

    /// Hands out one cut of the text: its code dropped, in spoken form, if anything of it is left to speak.
    fn hand_out(&mut self, raw: &str, clause: bool, done: &mut Vec<String>) {
        let outside = self.outside_fences(raw);
        let spoken = speakable(&outside, &self.language);
        if !spoken.chars().any(char::is_alphanumeric) {
            return;
        }
        done.push(spoken);
        self.started = true;
        // A clause is part of a sentence: the cap counts whole sentences.
        if clause {
            return;
        }
        self.count += 1;
        if self.max_sentences > 0 && self.count >= self.max_sentences {
            self.capped = true;
            self.pending.clear();
        }
    }

    /// The parts of `raw` outside fenced code blocks, following the fences it opens and closes.
    fn outside_fences(&mut self, raw: &str) -> String {
        let mut kept = String::new();
        for (n, part) in raw.split("```").enumerate() {
            if n > 0 {
                self.in_fence = !self.in_fence;
            }
            if !self.in_fence {
                kept.push_str(part);
                kept.push(' ');
            }
        }
        kept
    }
}

/// How many words `text` holds.
fn words(text: &[char]) -> usize {
    text.split(|c| c.is_whitespace())
        .filter(|w| w.iter().any(|c| c.is_alphanumeric()))
        .count()
}

/// `p.m.`, `U.S.`, `a.C.`: letters each followed by a dot, at least two of them.
fn is_dotted_acronym(word: &str) -> bool {
    let cs: Vec<char> = word.chars().collect();
    cs.len() >= 4
        && cs
            .chunks(2)
            .all(|pair| matches!(pair, [letter, '.'] if letter.is_alphabetic()))
}

/// How the words of one language read symbols and units.
struct Words {
    english: bool,
    percent: &'static str,
    degrees: &'static str,
    celsius: &'static str,
    fahrenheit: &'static str,
    and: &'static str,
    plus: &'static str,
    equals: &'static str,
    times: &'static str,
    about: &'static str,
    link: &'static str,
    /// (symbol, singular, plural)
    dollar: (&'static str, &'static str),
    euro: (&'static str, &'static str),
    pound: (&'static str, &'static str),
    abbreviations: &'static [(&'static str, &'static str)],
    /// (symbol, singular, plural), longest symbols first.
    units: &'static [(&'static str, &'static str, &'static str)],
}

const ENGLISH: Words = Words {
    english: true,
    percent: " percent ",
    degrees: " degrees ",
    celsius: " degrees Celsius ",
    fahrenheit: " degrees Fahrenheit ",
    and: " and ",
    plus: " plus ",
    equals: " equals ",
    times: " times ",
    about: " about ",
    link: "a link",
    dollar: ("dollar", "dollars"),
    euro: ("euro", "euros"),
    pound: ("pound", "pounds"),
    abbreviations: &[
        ("e.g.", "for example"),
        ("i.e.", "that is"),
        ("etc.", "et cetera"),
        ("vs.", "versus"),
        ("vs", "versus"),
        ("dr.", "Doctor"),
        ("mr.", "Mister"),
        ("mrs.", "Missus"),
    ],
    units: &[
        ("km/h", "kilometer per hour", "kilometers per hour"),
        ("km", "kilometer", "kilometers"),
        ("kg", "kilogram", "kilograms"),
        ("cm", "centimeter", "centimeters"),
        ("mm", "millimeter", "millimeters"),
        ("min", "minute", "minutes"),
        ("m", "meter", "meters"),
        ("g", "gram", "grams"),
        ("h", "hour", "hours"),
        ("s", "second", "seconds"),
    ],
};

const ITALIAN: Words = Words {
    english: false,
    percent: " per cento ",
    degrees: " gradi ",
    celsius: " gradi Celsius ",
    fahrenheit: " gradi Fahrenheit ",
    and: " e ",
    plus: " più ",
    equals: " uguale a ",
    times: " per ",
    about: " circa ",
    link: "un link",
    dollar: ("dollaro", "dollari"),
    euro: ("euro", "euro"),
    pound: ("sterlina", "sterline"),
    abbreviations: &[
        ("ecc.", "eccetera"),
        ("etc.", "eccetera"),
        ("es.", "per esempio"),
        ("p.es.", "per esempio"),
        ("sig.", "Signor"),
        ("sig.ra", "Signora"),
        ("dott.", "Dottor"),
    ],
    units: &[
        ("km/h", "chilometro orario", "chilometri orari"),
        ("km", "chilometro", "chilometri"),
        ("kg", "chilogrammo", "chilogrammi"),
        ("cm", "centimetro", "centimetri"),
        ("mm", "millimetro", "millimetri"),
        ("min", "minuto", "minuti"),
        ("m", "metro", "metri"),
        ("g", "grammo", "grammi"),
        ("h", "ora", "ore"),
        ("s", "secondo", "secondi"),
    ],
};

const ORDINALS: [&str; 31] = [
    "first",
    "second",
    "third",
    "fourth",
    "fifth",
    "sixth",
    "seventh",
    "eighth",
    "ninth",
    "tenth",
    "eleventh",
    "twelfth",
    "thirteenth",
    "fourteenth",
    "fifteenth",
    "sixteenth",
    "seventeenth",
    "eighteenth",
    "nineteenth",
    "twentieth",
    "twenty-first",
    "twenty-second",
    "twenty-third",
    "twenty-fourth",
    "twenty-fifth",
    "twenty-sixth",
    "twenty-seventh",
    "twenty-eighth",
    "twenty-ninth",
    "thirtieth",
    "thirty-first",
];

/// What a TTS should read of `text` in `language` (`en`, `it`; others read as English): no markdown, no code blocks,
/// no emoji, links named rather than spelled, symbols, units, currencies and abbreviations in words, whitespace
/// collapsed. Digits stay digits (the TTS speaks them).
pub fn speakable(text: &str, language: &str) -> String {
    let words = if language.to_ascii_lowercase().starts_with("it") {
        &ITALIAN
    } else {
        &ENGLISH
    };
    let outside_code: Vec<&str> = text.split("```").step_by(2).collect();
    let lines: Vec<String> = outside_code
        .join(" ")
        .lines()
        .map(without_line_markup)
        .filter(|line| !line.is_empty())
        .collect();
    let pictures_dropped: String = lines
        .join(" ")
        .chars()
        .filter(|&c| !is_pictograph(c))
        .collect();
    let linked = links_named(&without_link_syntax(&pictures_dropped), words);
    let grouped = if words.english {
        without_thousands_separators(&linked)
    } else {
        linked
    };
    let symbols = symbols_spoken(&grouped, words);
    tidy(&words_spoken(&symbols, words))
}

/// A line without its heading, quote, list and table markup.
fn without_line_markup(line: &str) -> String {
    let mut s = line.trim();
    if s.chars().count() >= 3 && s.chars().all(|c| matches!(c, '-' | '*' | '_' | '=' | ' ')) {
        return String::new();
    }
    let heading = s.trim_start_matches('#');
    if heading.len() != s.len() && (heading.is_empty() || heading.starts_with(' ')) {
        s = heading.trim_start();
    }
    while let Some(quoted) = s.strip_prefix('>') {
        s = quoted.trim_start();
    }
    for marker in ["- ", "* ", "+ ", "• "] {
        if let Some(item) = s.strip_prefix(marker) {
            s = item.trim_start();
            break;
        }
    }
    let digits = s.bytes().take_while(u8::is_ascii_digit).count();
    if (1..=3).contains(&digits) {
        let rest = &s[digits..];
        if let Some(item) = rest.strip_prefix(". ").or_else(|| rest.strip_prefix(") ")) {
            s = item.trim_start();
        }
    }
    s.replace('|', " ")
}

/// Emoji, pictographs, dingbats, arrows and the joiners and selectors that build emoji sequences.
fn is_pictograph(c: char) -> bool {
    matches!(c as u32,
        0x1F000..=0x1FAFF
        | 0x2190..=0x21FF
        | 0x2300..=0x23FF
        | 0x25A0..=0x27BF
        | 0x2B00..=0x2BFF
        | 0xFE00..=0xFE0F
        | 0x200D
        | 0x20E3
        | 0xE0000..=0xE007F
        | 0x3030
        | 0x303D
        | 0x3297
        | 0x3299)
}

/// `[text](url)` and `![text](url)` read as their text.
fn without_link_syntax(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(open) = rest.find('[') {
        let inside = &rest[open + 1..];
        let link = inside.find(']').and_then(|close| {
            let target = inside[close + 1..].strip_prefix('(')?;
            let end = target.find(')')?;
            Some((&inside[..close], &target[end + 1..]))
        });
        match link {
            Some((text, after)) => {
                out.push_str(rest[..open].strip_suffix('!').unwrap_or(&rest[..open]));
                out.push_str(text);
                rest = after;
            }
            None => {
                out.push_str(&rest[..=open]);
                rest = inside;
            }
        }
    }
    out.push_str(rest);
    out
}

/// Bare URLs read as "a link".
fn links_named(s: &str, words: &Words) -> String {
    let named: Vec<String> = s
        .split_whitespace()
        .map(|word| {
            let (lead, core, trail) = peel(word);
            let lower = core.to_ascii_lowercase();
            if lower.starts_with("http://")
                || lower.starts_with("https://")
                || lower.starts_with("www.")
            {
                format!("{lead}{}{trail}", words.link)
            } else {
                word.to_owned()
            }
        })
        .collect();
    named.join(" ")
}

/// `1,000,000` as `1000000` (English groups thousands with commas).
fn without_thousands_separators(s: &str) -> String {
    let cs: Vec<char> = s.chars().collect();
    let digit = |i: usize| cs.get(i).is_some_and(char::is_ascii_digit);
    cs.iter()
        .enumerate()
        .filter(|&(i, &c)| {
            let separator = c == ','
                && i > 0
                && digit(i - 1)
                && digit(i + 1)
                && digit(i + 2)
                && digit(i + 3)
                && !digit(i + 4);
            !separator
        })
        .map(|(_, &c)| c)
        .collect()
}

/// The end of the number starting at `start` (`start` itself when there is none): digits with single `.` or `,`
/// between them.
fn number_end(cs: &[char], start: usize) -> usize {
    let mut i = start;
    while i < cs.len() {
        let c = cs[i];
        let separator_inside =
            matches!(c, '.' | ',') && i > start && cs.get(i + 1).is_some_and(char::is_ascii_digit);
        if c.is_ascii_digit() || separator_inside {
            i += 1;
        } else {
            break;
        }
    }
    i
}

/// The number `out` ends with (spaces after it ignored), if it ends with one.
fn trailing_number(out: &str) -> Option<&str> {
    let trimmed = out.trim_end();
    let start = trimmed
        .char_indices()
        .rev()
        .take_while(|&(_, c)| c.is_ascii_digit() || matches!(c, '.' | ','))
        .last()
        .map(|(i, _)| i)?;
    let number = trimmed[start..].trim_start_matches(['.', ',']);
    number
        .starts_with(|c: char| c.is_ascii_digit())
        .then_some(number)
}

fn currency(number: &str, (one, many): (&str, &str)) -> String {
    format!(" {number} {} ", if number == "1" { one } else { many })
}

/// Symbols, currencies and inline markup read in words.
fn symbols_spoken(s: &str, words: &Words) -> String {
    let cs: Vec<char> = s.chars().collect();
    let mut out = String::with_capacity(s.len() + 16);
    let next_solid = |i: usize| cs[i + 1..].iter().find(|c| !c.is_whitespace()).copied();
    let mut i = 0;
    while i < cs.len() {
        let c = cs[i];
        let prev_solid = out.trim_end().chars().next_back();
        let between_digits = prev_solid.is_some_and(|p| p.is_ascii_digit())
            && next_solid(i).is_some_and(|n| n.is_ascii_digit());
        match c {
            '%' => out.push_str(words.percent),
            '°' => match cs.get(i + 1) {
                Some('C') if !cs.get(i + 2).is_some_and(|n| n.is_alphabetic()) => {
                    out.push_str(words.celsius);
                    i += 1;
                }
                Some('F') if !cs.get(i + 2).is_some_and(|n| n.is_alphabetic()) => {
                    out.push_str(words.fahrenheit);
                    i += 1;
                }
                _ => out.push_str(words.degrees),
            },
            '&' => out.push_str(words.and),
            '=' => out.push_str(words.equals),
            '+' if between_digits => out.push_str(words.plus),
            '*' if between_digits => out.push_str(words.times),
            '*' | '`' => {}
            '_' => {
                let joins = prev_solid.is_some_and(char::is_alphanumeric)
                    && cs.get(i + 1).is_some_and(|n| n.is_alphanumeric())
                    && out.ends_with(|p: char| p.is_alphanumeric());
                if joins {
                    out.push(' ');
                }
            }
            '~' => {
                if next_solid(i).is_some_and(|n| n.is_ascii_digit()) {
                    out.push_str(words.about);
                }
            }
            '$' | '€' | '£' => {
                let name = match c {
                    '$' => words.dollar,
                    '€' => words.euro,
                    _ => words.pound,
                };
                let start = i + 1 + cs[i + 1..].iter().take_while(|n| **n == ' ').count();
                let end = number_end(&cs, start);
                if end > start {
                    let number: String = cs[start..end].iter().collect();
                    out.push_str(&currency(&number, name));
                    i = end;
                    continue;
                }
                match trailing_number(&out).map(str::to_owned) {
                    Some(number) => {
                        let (one, many) = name;
                        out.push(' ');
                        out.push_str(if number == "1" { one } else { many });
                        out.push(' ');
                    }
                    None => out.push(c),
                }
            }
            _ => out.push(c),
        }
        i += 1;
    }
    out
}

/// A word split into leading punctuation, its core and trailing punctuation.
fn peel(word: &str) -> (&str, &str, &str) {
    let core_start = word
        .char_indices()
        .find(|&(_, c)| {
            !matches!(
                c,
                '(' | '[' | '{' | '"' | '\'' | '“' | '‘' | '«' | '¿' | '¡'
            )
        })
        .map_or(word.len(), |(i, _)| i);
    let (lead, rest) = word.split_at(core_start);
    let core = rest.trim_end_matches([
        '.', ',', ';', ':', '!', '?', ')', ']', '}', '"', '\'', '”', '’', '»', '…',
    ]);
    (lead, core, &rest[core.len()..])
}

fn is_number(s: &str) -> bool {
    let cs: Vec<char> = s.chars().collect();
    !cs.is_empty() && cs[0].is_ascii_digit() && number_end(&cs, 0) == cs.len()
}

/// An abbreviation read in full, keeping the punctuation around it.
fn abbreviation(word: &str, words: &Words, last: bool) -> Option<String> {
    let (lead, _, _) = peel(word);
    let rest = &word[lead.len()..];
    let middle = rest.trim_end_matches([',', ';', ':', '!', '?', ')', ']', '"', '\'', '”', '’']);
    let trail = &rest[middle.len()..];
    let lower = middle.to_lowercase();
    let (_, full) = words
        .abbreviations
        .iter()
        .find(|(short, _)| *short == lower)?;
    let mut spoken = String::from(*full);
    if middle.starts_with(char::is_uppercase)
        && let Some(first) = spoken.chars().next()
    {
        spoken = first.to_uppercase().chain(spoken.chars().skip(1)).collect();
    }
    let ends = last && trail.is_empty() && (lower == "etc." || lower == "ecc.");
    Some(format!(
        "{lead}{spoken}{}{trail}",
        if ends { "." } else { "" }
    ))
}

/// The unit `symbol` is one of, read after `number`.
fn unit<'w>(symbol: &str, number: &str, words: &'w Words) -> Option<&'w str> {
    let (_, one, many) = words.units.iter().find(|(s, _, _)| *s == symbol)?;
    Some(if number == "1" { one } else { many })
}

/// Abbreviations, ordinals and units read in words.
fn words_spoken(s: &str, words: &Words) -> String {
    let all: Vec<&str> = s.split_whitespace().collect();
    let mut out: Vec<String> = Vec::with_capacity(all.len());
    let mut i = 0;
    while i < all.len() {
        let word = all[i];
        i += 1;
        if let Some(full) = abbreviation(word, words, i == all.len()) {
            out.push(full);
            continue;
        }
        let (lead, core, trail) = peel(word);
        if words.english
            && let Some(ordinal) = ordinal(core)
        {
            out.push(format!("{lead}{ordinal}{trail}"));
            continue;
        }
        let digits: Vec<char> = core.chars().collect();
        let split = number_end(&digits, 0);
        if split > 0 && split < digits.len() {
            let number: String = digits[..split].iter().collect();
            let symbol: String = digits[split..].iter().collect();
            let decade = symbol == "s" && number.ends_with('0');
            if !decade && let Some(name) = unit(&symbol, &number, words) {
                out.push(format!("{lead}{number} {name}{trail}"));
                continue;
            }
        }
        if is_number(core)
            && trail.is_empty()
            && let Some(next) = all.get(i)
        {
            let (next_lead, symbol, next_trail) = peel(next);
            if next_lead.is_empty()
                && let Some(name) = unit(symbol, core, words)
            {
                out.push(format!("{lead}{core} {name}{next_trail}"));
                i += 1;
                continue;
            }
        }
        out.push(word.to_owned());
    }
    out.join(" ")
}

/// `1st` to `31st` in words.
fn ordinal(core: &str) -> Option<&'static str> {
    let digits = core.bytes().take_while(u8::is_ascii_digit).count();
    let suffix = core[digits..].to_ascii_lowercase();
    if digits == 0 || digits > 2 || !matches!(suffix.as_str(), "st" | "nd" | "rd" | "th") {
        return None;
    }
    let n: usize = core[..digits].parse().ok()?;
    ORDINALS.get(n.checked_sub(1)?).copied()
}

/// Whitespace collapsed, no space before punctuation or inside brackets.
fn tidy(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for word in s.split_whitespace() {
        let glued = word.starts_with([',', '.', ';', ':', '!', '?', ')', ']', '}'])
            || out.ends_with(['(', '[', '{']);
        if !out.is_empty() && !glued {
            out.push(' ');
        }
        out.push_str(word);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn split_all(text: &str) -> Vec<String> {
        let mut sentences = Sentences::new(0);
        let mut out = sentences.push(text);
        out.extend(sentences.finish());
        out
    }

    #[test]
    fn the_first_sentence_is_cut_at_a_clause_once_it_has_three_words_and_the_cap_counts_sentences()
    {
        let mut split = Sentences::new(2);
        let mut out =
            split.push("Well, the sky looks blue to us, because air scatters blue light. ");
        out.extend(split.push("It is called Rayleigh scattering, after a physicist. A third one."));
        out.extend(split.finish());
        assert_eq!(
            out,
            [
                "Well, the sky looks blue to us,",
                "because air scatters blue light.",
                "It is called Rayleigh scattering, after a physicist.",
            ]
        );
        assert!(split.capped());
    }

    /// The first chunk handed out for `text` (a reply of SmolLM2-135M), and the rest.
    fn first_chunk(text: &str, language: &str) -> Vec<String> {
        let mut split = Sentences::new(0).in_language(language);
        let mut out = Vec::new();
        for piece in text.split_inclusive(' ') {
            out.extend(split.push(piece));
        }
        out.extend(split.finish());
        out
    }

    #[test]
    fn the_first_chunk_ends_at_the_first_natural_break_after_three_words() {
        // Replies the model gave in bench/llm/conversation.toml's set.
        assert_eq!(
            first_chunk(
                "The sky appears blue because of a process called Rayleigh scattering. It is light.",
                "en"
            ),
            [
                "The sky appears blue",
                "because of a process called Rayleigh scattering.",
                "It is light."
            ]
        );
        assert_eq!(
            first_chunk(
                "People laugh for many reasons, but one of them is joy.",
                "en"
            ),
            ["People laugh for many reasons,", "but one of them is joy."]
        );
        assert_eq!(
            first_chunk(
                "The moon is so bright because it reflects the light of the sun.",
                "en"
            ),
            [
                "The moon is so bright",
                "because it reflects the light of the sun."
            ]
        );
        assert_eq!(
            first_chunk("Il cielo è blu perché la luce si diffonde.", "it"),
            ["Il cielo è blu", "perché la luce si diffonde."]
        );
    }

    #[test]
    fn the_first_chunk_is_not_cut_mid_phrase() {
        // Too early: fewer than three words before the break.
        assert_eq!(
            first_chunk("Yes, I can see you.", "en"),
            ["Yes, I can see you."]
        );
        assert_eq!(first_chunk("Well, but why?", "en"), ["Well, but why?"]);
        // "and" joins words as often as clauses: red | and blue would be ugly.
        assert_eq!(
            first_chunk("I like red and blue and green a lot.", "en"),
            ["I like red and blue and green a lot."]
        );
        // A number after a comma belongs with what came before it.
        assert_eq!(
            first_chunk("Today is December 5, 2026, a Saturday.", "en"),
            ["Today is December 5, 2026,", "a Saturday."]
        );
        // An opener must be a whole word: "butter" is not "but", "whichever" not "which".
        assert_eq!(
            first_chunk("I would like butter whichever bread it is.", "en"),
            ["I would like butter whichever bread it is."]
        );
        // Only the first sentence is cut early.
        assert_eq!(
            first_chunk("Hello there! The sky is blue because of the air.", "en"),
            ["Hello there!", "The sky is blue because of the air."]
        );
    }

    #[test]
    fn an_opener_still_being_written_waits_for_its_end() {
        let mut split = Sentences::new(0);
        assert!(split.push("The sky is blue bec").is_empty());
        assert!(split.push("ause").is_empty(), "the word is not over");
        assert_eq!(split.push(" air"), ["The sky is blue"]);
        assert_eq!(split.finish().as_deref(), Some("because air"));
    }

    fn split_char_by_char(text: &str) -> Vec<String> {
        let mut sentences = Sentences::new(0);
        let mut out = Vec::new();
        for c in text.chars() {
            out.extend(sentences.push(c.encode_utf8(&mut [0; 4])));
        }
        out.extend(sentences.finish());
        out
    }

    #[test]
    fn sentences_end_at_terminals_followed_by_whitespace() {
        assert_eq!(
            split_all("Hello there! How are you? I am fine. Wait… what"),
            [
                "Hello there!",
                "How are you?",
                "I am fine.",
                "Wait…",
                "what"
            ]
        );
    }

    #[test]
    fn a_sentence_is_handed_out_only_once_the_next_character_is_known() {
        let mut sentences = Sentences::new(0);
        assert!(sentences.push("It is 3").is_empty());
        assert!(sentences.push(".").is_empty());
        assert!(sentences.push("5 metres").is_empty());
        assert!(sentences.push(" long.").is_empty());
        assert_eq!(sentences.push(" Next"), ["It is 3.5 metres long."]);
        assert_eq!(sentences.finish().as_deref(), Some("Next"));
        assert_eq!(sentences.count(), 2);
    }

    #[test]
    fn a_newline_ends_a_sentence() {
        assert_eq!(
            split_all("First line\nSecond line\n\nThird"),
            ["First line", "Second line", "Third"]
        );
    }

    #[test]
    fn abbreviations_and_decimals_do_not_end_sentences() {
        assert_eq!(
            split_all("Mr. Smith met Dr. Who at St. Paul. It cost 3.5 euros, e.g. a coffee. Done."),
            [
                "Mister Smith met Doctor Who at St. Paul.",
                "It cost 3.5 euros, for example a coffee.",
                "Done."
            ]
        );
    }

    #[test]
    fn etc_ends_a_sentence_only_before_a_capital() {
        assert_eq!(
            split_all("Apples, pears etc. and more. Apples etc. Then bread."),
            [
                "Apples, pears et cetera and more.",
                "Apples et cetera.",
                "Then bread."
            ]
        );
        let mut sentences = Sentences::new(0);
        assert!(
            sentences.push("Apples etc. ").is_empty(),
            "the next word decides"
        );
        assert_eq!(sentences.push("then"), Vec::<String>::new());
    }

    #[test]
    fn dotted_acronyms_end_a_sentence_only_before_a_capital() {
        assert_eq!(
            split_all("It is 3 p.m. now. The U.S. is big. Come at 5 p.m. Then eat."),
            [
                "It is 3 p.m. now.",
                "The U.S. is big.",
                "Come at 5 p.m.",
                "Then eat."
            ]
        );
    }

    #[test]
    fn quotes_and_emphasis_close_a_sentence() {
        assert_eq!(
            split_all("He said \"yes.\" Then **stop.** Go"),
            ["He said \"yes.\"", "Then stop.", "Go"]
        );
    }

    #[test]
    fn list_numbers_do_not_end_sentences() {
        assert_eq!(
            split_all("Steps:\n1. Open the door\n2. Walk in. Sit down.\nWe met at 5. Bye"),
            [
                "Steps:",
                "Open the door",
                "Walk in.",
                "Sit down.",
                "We met at 5.",
                "Bye"
            ]
        );
    }

    #[test]
    fn long_text_without_punctuation_is_cut_at_a_word_after_200_characters() {
        let text = "word ".repeat(100);
        let sentences = split_all(&text);
        assert!(sentences.len() > 1, "{sentences:?}");
        for sentence in &sentences {
            assert!(sentence.chars().count() <= SOFT_LIMIT + 5, "{sentence}");
            assert!(
                sentence.split(' ').all(|w| w == "word"),
                "cut inside a word: {sentence}"
            );
        }
    }

    #[test]
    fn a_run_without_spaces_is_cut_hard() {
        let sentences = split_all(&"x".repeat(1000));
        assert_eq!(sentences.len(), 3);
        assert_eq!(sentences[0].chars().count(), HARD_LIMIT);
    }

    #[test]
    fn code_blocks_are_never_spoken() {
        assert_eq!(
            split_all("Run this:\n```bash\nls -la. rm it.\n```\nThat lists files."),
            ["Run this:", "That lists files."]
        );
        assert_eq!(
            split_all("Look:\n```\nprint(1). x\n"),
            ["Look:"],
            "an unclosed block is dropped too"
        );
    }

    #[test]
    fn empty_and_symbol_only_sentences_are_skipped_and_not_counted() {
        let mut sentences = Sentences::new(0);
        assert_eq!(sentences.push("... 🙂 ! Hi. "), ["Hi."]);
        assert_eq!(sentences.count(), 1);
        assert_eq!(sentences.finish(), None);
    }

    #[test]
    fn the_splitter_stops_at_its_limit() {
        let mut sentences = Sentences::new(2);
        assert_eq!(sentences.push("One. Two. Three. "), ["One.", "Two."]);
        assert!(sentences.capped());
        assert!(sentences.push("Four. Five. ").is_empty());
        assert_eq!(sentences.finish(), None);
        assert_eq!(sentences.count(), 2);
    }

    #[test]
    fn the_splitter_speaks_its_language() {
        let mut sentences = Sentences::new(0).in_language("it");
        assert_eq!(
            sentences.push("Fa 20°C oggi. Sì"),
            ["Fa 20 gradi Celsius oggi."]
        );
        assert_eq!(sentences.finish().as_deref(), Some("Sì"));
    }

    #[test]
    fn pieces_split_anywhere_give_the_same_sentences() {
        let texts = [
            "Hello there! It is 3.5 km away, e.g. near St. Mark's. Done etc. Then more.\n- item\n1. first",
            "Cost: $1,000 (i.e. a lot)… Really?! Yes.\n```\ncode. here\n```\nAfter.",
            "Città più bella è Roma. Sig. Rossi, ecc. Poi.",
            &"long words without any punctuation at all ".repeat(12),
        ];
        for text in texts {
            let whole = split_all(text);
            assert_eq!(split_char_by_char(text), whole, "{text}");
            let boundaries: Vec<usize> = text.char_indices().map(|(i, _)| i).collect();
            for &at in &boundaries {
                let mut sentences = Sentences::new(0);
                let mut out = sentences.push(&text[..at]);
                out.extend(sentences.push(&text[at..]));
                out.extend(sentences.finish());
                assert_eq!(out, whole, "{text} split at {at}");
            }
        }
    }

    /// A small deterministic generator of arbitrary text, so the test needs no randomness crate.
    fn arbitrary_text(seed: &mut u64, length: usize) -> String {
        const TRICKY: &[char] = &[
            '.', '!', '?', '…', ' ', '\n', '`', '*', '_', '#', '[', ']', '(', ')', '$', '€', '%',
            '°', '&', '+', '=', ',', '1', '9', 'e', 'E', 'g', 'é', 'ß', '日', '🙂', '👍',
            '\u{200d}', '\u{fe0f}', 'İ', '~', '|',
        ];
        let mut text = String::new();
        for _ in 0..length {
            *seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let r = (*seed >> 33) as u32;
            let c = if r.is_multiple_of(3) {
                char::from_u32(r % 0x11_0000).unwrap_or('\u{fffd}')
            } else {
                TRICKY[(r as usize) % TRICKY.len()]
            };
            text.push(c);
        }
        text
    }

    #[test]
    fn arbitrary_unicode_never_panics_and_splits_the_same_way_in_any_pieces() {
        let mut seed = 7;
        for round in 0..300 {
            let text = arbitrary_text(&mut seed, 1 + round % 60);
            for language in ["en", "it"] {
                let _ = speakable(&text, language);
            }
            let whole = split_all(&text);
            assert_eq!(split_char_by_char(&text), whole, "{text:?}");
            for (at, _) in text.char_indices() {
                let mut sentences = Sentences::new(3);
                let _ = sentences.push(&text[..at]);
                let _ = sentences.push(&text[at..]);
                let _ = sentences.finish();
            }
        }
    }

    #[test]
    fn markdown_is_not_read() {
        assert_eq!(speakable("## The **big** _news_", "en"), "The big news");
        assert_eq!(speakable("- first item", "en"), "first item");
        assert_eq!(speakable("* starred item", "en"), "starred item");
        assert_eq!(speakable("3. third item", "en"), "third item");
        assert_eq!(speakable("> quoted", "en"), "quoted");
        assert_eq!(speakable("Use `ls` now", "en"), "Use ls now");
        assert_eq!(
            speakable("Before ```rust\nfn main() {}\n``` after", "en"),
            "Before after"
        );
        assert_eq!(speakable("my_variable_name", "en"), "my variable name");
        assert_eq!(speakable("---", "en"), "");
    }

    #[test]
    fn links_are_named_not_spelled() {
        assert_eq!(
            speakable("See [the docs](https://x.org/a_b?c=d&e) now.", "en"),
            "See the docs now."
        );
        assert_eq!(speakable("![a cat](cat.png)", "en"), "a cat");
        assert_eq!(
            speakable("Go to https://example.com/a_b?x=1&y=2.", "en"),
            "Go to a link."
        );
        assert_eq!(
            speakable("Vai su www.example.it, grazie", "it"),
            "Vai su un link, grazie"
        );
        assert_eq!(
            speakable("an [unclosed bracket", "en"),
            "an [unclosed bracket"
        );
    }

    #[test]
    fn emoji_and_pictographs_are_dropped() {
        assert_eq!(
            speakable("Great job 👍🏽! ⭐ Family: 👨‍👩‍👧 ✅ ➡️ done", "en"),
            "Great job! Family: done"
        );
        assert_eq!(speakable("Ciao 😀", "it"), "Ciao");
    }

    #[test]
    fn whitespace_is_collapsed() {
        assert_eq!(speakable("  a \t b\n\n c  ", "en"), "a b c");
        assert_eq!(
            speakable("25°C (77°F).", "en"),
            "25 degrees Celsius (77 degrees Fahrenheit)."
        );
        assert_eq!(speakable("( ~5 )", "en"), "(about 5)");
    }

    #[test]
    fn symbols_are_read_in_words() {
        assert_eq!(speakable("50% of it", "en"), "50 percent of it");
        assert_eq!(speakable("il 50%.", "it"), "il 50 per cento.");
        assert_eq!(
            speakable("It is 21°C, 70°F, a 90° turn", "en"),
            "It is 21 degrees Celsius, 70 degrees Fahrenheit, a 90 degrees turn"
        );
        assert_eq!(speakable("Sono 21 °C", "it"), "Sono 21 gradi Celsius");
        assert_eq!(speakable("Tom & Jerry", "en"), "Tom and Jerry");
        assert_eq!(speakable("Tom & Jerry", "it"), "Tom e Jerry");
        assert_eq!(speakable("2 + 2 = 4", "en"), "2 plus 2 equals 4");
        assert_eq!(speakable("2+2=4", "it"), "2 più 2 uguale a 4");
        assert_eq!(speakable("3*4", "en"), "3 times 4");
        assert_eq!(speakable("C++ rocks", "en"), "C++ rocks");
        assert_eq!(speakable("~5 minutes", "en"), "about 5 minutes");
    }

    #[test]
    fn currencies_follow_their_amount() {
        assert_eq!(speakable("It costs $5.", "en"), "It costs 5 dollars.");
        assert_eq!(speakable("Just $1", "en"), "Just 1 dollar");
        assert_eq!(
            speakable("€5 or 5€ or 5 €", "en"),
            "5 euros or 5 euros or 5 euros"
        );
        assert_eq!(speakable("Costa 5€ o €1", "it"), "Costa 5 euro o 1 euro");
        assert_eq!(
            speakable("$2,500 and £3", "en"),
            "2500 dollars and 3 pounds"
        );
        assert_eq!(speakable("a lone $ sign", "en"), "a lone $ sign");
    }

    #[test]
    fn units_after_a_number_are_read_in_words() {
        assert_eq!(
            speakable("It is 5 km away", "en"),
            "It is 5 kilometers away"
        );
        assert_eq!(
            speakable("1 kg, 3.5kg and 10 cm.", "en"),
            "1 kilogram, 3.5 kilograms and 10 centimeters."
        );
        assert_eq!(
            speakable("At 50 km/h for 2 h 30 min", "en"),
            "At 50 kilometers per hour for 2 hours 30 minutes"
        );
        assert_eq!(
            speakable("5mm 2 m 100g 4 s", "en"),
            "5 millimeters 2 meters 100 grams 4 seconds"
        );
        assert_eq!(
            speakable("A 1,5 km, 1 h e 20 s.", "it"),
            "A 1,5 chilometri, 1 ora e 20 secondi."
        );
        assert_eq!(
            speakable("Music of the 80s", "en"),
            "Music of the 80s",
            "a decade is no time"
        );
        assert_eq!(
            speakable("I am fine, m is a letter", "en"),
            "I am fine, m is a letter"
        );
    }

    #[test]
    fn abbreviations_are_read_in_full() {
        assert_eq!(
            speakable("Fruit, e.g. apples, i.e. food, etc.", "en"),
            "Fruit, for example apples, that is food, et cetera."
        );
        assert_eq!(
            speakable("E.g. this vs. that", "en"),
            "For example this versus that"
        );
        assert_eq!(
            speakable("Mr. and Mrs. Smith and Dr. No", "en"),
            "Mister and Missus Smith and Doctor No"
        );
        assert_eq!(
            speakable("Frutta, es. mele, ecc. Il Sig. Rossi", "it"),
            "Frutta, per esempio mele, eccetera Il Signor Rossi"
        );
        assert_eq!(
            speakable("Mr. Rossi", "it"),
            "Mr. Rossi",
            "English abbreviations are English only"
        );
    }

    #[test]
    fn numbers_stay_digits_but_lose_thousands_separators() {
        assert_eq!(
            speakable("1,000 people and 12,345,678 ants", "en"),
            "1000 people and 12345678 ants"
        );
        assert_eq!(speakable("1,2,3 and 3.14", "en"), "1,2,3 and 3.14");
        assert_eq!(
            speakable("1,000 persone", "it"),
            "1,000 persone",
            "Italian commas are decimals"
        );
    }

    #[test]
    fn english_ordinals_up_to_31_are_words() {
        assert_eq!(
            speakable("The 1st, 2nd, 3rd and 4th.", "en"),
            "The first, second, third and fourth."
        );
        assert_eq!(
            speakable("On the 21st and 31st but not the 32nd", "en"),
            "On the twenty-first and thirty-first but not the 32nd"
        );
        assert_eq!(speakable("il 1st", "it"), "il 1st");
    }
}
