//! A file cut into passages, the pieces the agent may speak: a new passage at every heading and blank line, none
//! longer than [`MAX_CHARS`] (a long paragraph is cut at sentence ends), each with its file and heading path, in
//! plain text.

use crate::folder::{Format, SourceFile};
use crate::markup;

/// The longest passage, in characters: about 30 seconds of speech, and short enough that a match in it is about
/// the question rather than somewhere in a page.
pub const MAX_CHARS: usize = 600;

/// What joins the headings of a heading path: "Commands > Looking around".
pub const HEADING_SEPARATOR: &str = " > ";

/// One passage of a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Passage {
    /// The file, relative to the folder, `/`-separated.
    pub file: String,
    /// The headings above the passage, outermost first, joined by [`HEADING_SEPARATOR`]; empty before the first
    /// heading and in text files.
    pub heading: String,
    /// Plain text, markup removed, on one line.
    pub text: String,
}

/// The passages of a file, in order.
pub fn split(file: &SourceFile) -> Vec<Passage> {
    let blocks = match file.format {
        Format::Markdown => markdown_blocks(&file.text),
        Format::Text => text_blocks(&file.text),
    };
    let mut out = Vec::new();
    for (heading, text) in blocks {
        for piece in limit(&text, MAX_CHARS) {
            out.push(Passage {
                file: file.relative.clone(),
                heading: heading.clone(),
                text: piece,
            });
        }
    }
    out
}

/// A text file's paragraphs, each on one line, with no heading.
fn text_blocks(text: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut paragraph = String::new();
    for line in text.lines().chain(std::iter::once("")) {
        if line.trim().is_empty() {
            let block = markup::collapse(&paragraph);
            if !block.is_empty() {
                out.push((String::new(), block));
            }
            paragraph.clear();
        } else {
            paragraph.push(' ');
            paragraph.push_str(line);
        }
    }
    out
}

/// A line of a paragraph as written: list items and table rows are pieces of their own, read as sentences.
struct Piece {
    text: String,
    item: bool,
}

/// The paragraph being gathered under the current headings.
#[derive(Default)]
struct Gathering {
    headings: Vec<(usize, String)>,
    pieces: Vec<Piece>,
    out: Vec<(String, String)>,
}

impl Gathering {
    fn heading_path(&self) -> String {
        let names: Vec<&str> = self.headings.iter().map(|(_, h)| h.as_str()).collect();
        names.join(HEADING_SEPARATOR)
    }

    fn flush(&mut self) {
        let mut text = String::new();
        let count = self.pieces.len();
        for (i, piece) in self.pieces.drain(..).enumerate() {
            let plain = markup::plain(&piece.text);
            if plain.is_empty() {
                continue;
            }
            if !text.is_empty() {
                text.push(' ');
            }
            text.push_str(&plain);
            // A list item without its own full stop would run into the next one when spoken.
            if piece.item && i + 1 < count && !plain.ends_with(['.', '!', '?', ':', ';']) {
                text.push('.');
            }
        }
        if !text.is_empty() {
            let heading = self.heading_path();
            self.out.push((heading, text));
        }
    }

    fn heading(&mut self, level: usize, title: &str) {
        self.flush();
        while self.headings.last().is_some_and(|(l, _)| *l >= level) {
            self.headings.pop();
        }
        let title = markup::plain(title);
        if !title.is_empty() {
            self.headings.push((level, title));
        }
    }

    fn push(&mut self, text: &str, item: bool) {
        match self.pieces.last_mut() {
            Some(last) if !item => {
                last.text.push(' ');
                last.text.push_str(text);
            }
            _ => self.pieces.push(Piece {
                text: text.to_string(),
                item,
            }),
        }
    }
}

/// A Markdown file's paragraphs with their heading paths.
fn markdown_blocks(text: &str) -> Vec<(String, String)> {
    let text = markup::strip_comments(text);
    let mut lines = text.lines().peekable();
    // YAML front matter is metadata, not something to say.
    if lines.peek().is_some_and(|l| l.trim() == "---") {
        lines.next();
        for line in lines.by_ref() {
            if matches!(line.trim(), "---" | "...") {
                break;
            }
        }
    }
    let mut g = Gathering::default();
    let mut fence: Option<&str> = None;
    for line in lines {
        let trimmed = line.trim();
        if let Some(marker) = fence {
            if trimmed.starts_with(marker) {
                fence = None;
                g.flush();
            } else if !trimmed.is_empty() {
                // Code is kept as words (a command to type is worth saying), each line a piece.
                g.pieces.push(Piece {
                    text: trimmed.replace(['`', '*', '_', '[', ']', '<', '>'], " "),
                    item: true,
                });
            }
            continue;
        }
        if trimmed.starts_with("```") || trimmed.starts_with("~~~") {
            g.flush();
            fence = Some(&trimmed[..3]);
            continue;
        }
        if trimmed.is_empty() {
            g.flush();
            continue;
        }
        if let Some((level, title)) = atx_heading(trimmed) {
            g.heading(level, title);
            continue;
        }
        if let Some(level) = setext_underline(trimmed) {
            // A one-line paragraph underlined with `===` or `---` is a heading.
            if g.pieces.len() == 1 && !g.pieces[0].item {
                let title = g.pieces.remove(0).text;
                g.heading(level, &title);
            } else {
                g.flush();
            }
            continue;
        }
        if is_rule(trimmed) || is_reference_definition(trimmed) || is_table_separator(trimmed) {
            continue;
        }
        let content = strip_quote(trimmed);
        if content.starts_with('|') {
            let cells: Vec<&str> = content
                .trim_matches('|')
                .split('|')
                .map(str::trim)
                .filter(|c| !c.is_empty())
                .collect();
            g.push(&cells.join(", "), true);
        } else if let Some(item) = list_item(content) {
            g.push(item, true);
        } else if !content.is_empty() {
            g.push(content, false);
        }
    }
    g.flush();
    g.out
}

/// `## Title ##` as (2, "Title").
fn atx_heading(line: &str) -> Option<(usize, &str)> {
    let level = line.chars().take_while(|&c| c == '#').count();
    if level == 0 || level > 6 {
        return None;
    }
    let rest = &line[level..];
    if !rest.is_empty() && !rest.starts_with([' ', '\t']) {
        return None;
    }
    Some((level, rest.trim().trim_end_matches('#').trim()))
}

fn setext_underline(line: &str) -> Option<usize> {
    if line.len() >= 3 && line.chars().all(|c| c == '=') {
        Some(1)
    } else if line.len() >= 3 && line.chars().all(|c| c == '-') {
        Some(2)
    } else {
        None
    }
}

/// A thematic break: `***`, `___`, `- - -` (a plain `---` is taken as a setext underline first).
fn is_rule(line: &str) -> bool {
    let marks: String = line.chars().filter(|c| !c.is_whitespace()).collect();
    marks.len() >= 3
        && ['-', '*', '_']
            .iter()
            .any(|m| marks.chars().all(|c| c == *m))
}

/// `[label]: https://...`: where a reference link points, nothing to say.
fn is_reference_definition(line: &str) -> bool {
    line.starts_with('[') && line.find("]:").is_some_and(|i| i > 1)
}

/// `|---|:---:|`.
fn is_table_separator(line: &str) -> bool {
    line.contains('-')
        && line.contains('|')
        && line
            .chars()
            .all(|c| matches!(c, '|' | '-' | ':' | ' ' | '\t'))
}

fn strip_quote(line: &str) -> &str {
    let mut rest = line;
    while let Some(r) = rest.strip_prefix('>') {
        rest = r.trim_start();
    }
    rest
}

/// The text of a list item (`- x`, `* x`, `+ x`, `1. x`, `2) x`, with a task box dropped), or `None`.
fn list_item(line: &str) -> Option<&str> {
    let rest = if let Some(r) = line
        .strip_prefix("- ")
        .or_else(|| line.strip_prefix("* "))
        .or_else(|| line.strip_prefix("+ "))
    {
        r
    } else {
        let digits = line.chars().take_while(char::is_ascii_digit).count();
        if digits == 0 || digits > 9 {
            return None;
        }
        line[digits..]
            .strip_prefix(". ")
            .or_else(|| line[digits..].strip_prefix(") "))?
    };
    let rest = rest.trim_start();
    Some(
        rest.strip_prefix("[ ] ")
            .or_else(|| rest.strip_prefix("[x] "))
            .or_else(|| rest.strip_prefix("[X] "))
            .unwrap_or(rest),
    )
}

/// `text` cut into pieces of at most `max` characters: whole sentences together while they fit, a sentence longer
/// than `max` cut between words, a word longer than `max` cut anywhere.
fn limit(text: &str, max: usize) -> Vec<String> {
    if text.chars().count() <= max {
        return vec![text.to_string()];
    }
    let mut out = Vec::new();
    let mut current = String::new();
    for sentence in sentences(text) {
        let sentence_chars = sentence.chars().count();
        let current_chars = current.chars().count();
        if current_chars > 0 && current_chars + 1 + sentence_chars <= max {
            current.push(' ');
            current.push_str(sentence);
            continue;
        }
        if !current.is_empty() {
            out.push(std::mem::take(&mut current));
        }
        if sentence_chars <= max {
            current.push_str(sentence);
        } else {
            let mut words = by_words(sentence, max);
            if let Some(last) = words.pop() {
                out.extend(words);
                current = last;
            }
        }
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

/// The sentences of `text`: each ends after `.`, `!` or `?` (and any closing quote or bracket) before a space.
fn sentences(text: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut start = 0;
    let bytes = text.as_bytes();
    for (i, c) in text.char_indices() {
        if c != ' ' || i == 0 {
            continue;
        }
        let before = text[..i].trim_end_matches(['"', '\'', ')', ']', '\u{201d}', '\u{2019}']);
        if before.ends_with(['.', '!', '?']) && i > start {
            out.push(text[start..i].trim());
            start = i + 1;
        }
    }
    if start < bytes.len() {
        out.push(text[start..].trim());
    }
    out.retain(|s| !s.is_empty());
    out
}

fn by_words(sentence: &str, max: usize) -> Vec<String> {
    let mut out = Vec::new();
    let mut current = String::new();
    for word in sentence.split(' ') {
        let mut word = word.to_string();
        // A "word" longer than a passage (a long address) is cut where it must be.
        while word.chars().count() > max {
            let head: String = word.chars().take(max).collect();
            word = word.chars().skip(max).collect();
            if !current.is_empty() {
                out.push(std::mem::take(&mut current));
            }
            out.push(head);
        }
        if !current.is_empty() && current.chars().count() + 1 + word.chars().count() > max {
            out.push(std::mem::take(&mut current));
        }
        if !current.is_empty() {
            current.push(' ');
        }
        current.push_str(&word);
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn md(text: &str) -> Vec<Passage> {
        split(&SourceFile {
            relative: "guide/commands.md".into(),
            format: Format::Markdown,
            text: text.into(),
        })
    }

    #[test]
    fn a_heading_starts_a_new_passage_with_its_heading_path() {
        let passages = md("# Commands\n\nSay hello.\n\n## Looking around\n\nAsk what I see.\n");
        assert_eq!(passages.len(), 2);
        assert_eq!(passages[0].heading, "Commands");
        assert_eq!(passages[0].text, "Say hello.");
        assert_eq!(passages[1].heading, "Commands > Looking around");
        assert_eq!(passages[1].text, "Ask what I see.");
        assert_eq!(passages[1].file, "guide/commands.md");
    }

    #[test]
    fn a_blank_line_starts_a_new_passage_and_a_paragraph_joins_its_lines() {
        let passages = md("One line\nand its continuation.\n\nAnother paragraph.");
        let texts: Vec<&str> = passages.iter().map(|p| p.text.as_str()).collect();
        assert_eq!(
            texts,
            ["One line and its continuation.", "Another paragraph."]
        );
    }

    #[test]
    fn a_shallower_heading_closes_the_deeper_ones() {
        let passages = md("# A\n## B\n### C\ntext c\n## D\ntext d");
        assert_eq!(passages[0].heading, "A > B > C");
        assert_eq!(passages[1].heading, "A > D");
    }

    #[test]
    fn markup_is_stripped_to_speakable_text() {
        let passages = md(
            "## The `page`\n\nOpen **the page** at [this link](http://x/) and say *hello*.\n\n---\n\n[x]: http://y\n",
        );
        assert_eq!(passages.len(), 1);
        assert_eq!(passages[0].heading, "The page");
        assert_eq!(
            passages[0].text,
            "Open the page at this link and say hello."
        );
        for p in &passages {
            assert!(!p.text.contains(['#', '*', '`', '(']), "{}", p.text);
        }
    }

    #[test]
    fn list_items_are_read_as_sentences() {
        let passages =
            md("You can say:\n\n- what time is it\n- read the code\n  on the card\n- stop\n");
        assert_eq!(
            passages[1].text,
            "what time is it. read the code on the card. stop"
        );
    }

    #[test]
    fn a_table_reads_as_rows_of_cells() {
        let passages = md("| say | does |\n|---|---|\n| stop | cancels |\n");
        assert_eq!(passages[0].text, "say, does. stop, cancels");
    }

    #[test]
    fn a_long_paragraph_is_cut_at_sentence_ends_within_the_limit() {
        let sentence = "This sentence is about fifty characters long, ok. ";
        let passages = md(&sentence.repeat(30));
        assert!(passages.len() > 1);
        for p in &passages {
            assert!(p.text.chars().count() <= MAX_CHARS, "{}", p.text.len());
            assert!(p.text.ends_with('.'), "{}", p.text);
        }
        let words: usize = passages.iter().map(|p| p.text.split(' ').count()).sum();
        assert_eq!(words, 30 * 8);
    }

    #[test]
    fn a_sentence_longer_than_the_limit_is_cut_between_words() {
        let text = "word ".repeat(400);
        let passages = md(&text);
        assert!(passages.iter().all(|p| p.text.chars().count() <= MAX_CHARS));
        assert_eq!(
            passages
                .iter()
                .map(|p| p.text.split(' ').count())
                .sum::<usize>(),
            400
        );
    }

    #[test]
    fn front_matter_and_code_fences_are_handled() {
        let passages = md("---\ntitle: x\n---\n# T\n\n```sh\nmake run\n```\n\nAfter.");
        let texts: Vec<&str> = passages.iter().map(|p| p.text.as_str()).collect();
        assert_eq!(texts, ["make run", "After."]);
    }

    #[test]
    fn a_text_file_is_split_into_paragraphs_without_headings() {
        let passages = split(&SourceFile {
            relative: "hours.txt".into(),
            format: Format::Text,
            text: "# not a heading\nOpen at nine.\n\n\nClosed on Sunday.\n".into(),
        });
        assert_eq!(passages.len(), 2);
        assert_eq!(passages[0].heading, "");
        assert_eq!(passages[0].text, "# not a heading Open at nine.");
        assert_eq!(passages[1].text, "Closed on Sunday.");
    }
}
