//! Markdown's inline markup taken out of a text so that it reads aloud: emphasis, code spans, links (their text
//! kept, their address dropped), images (their description kept), HTML tags and comments.

/// `text` without HTML comments (`<!-- ... -->`), which may span lines; an unclosed one runs to the end.
pub fn strip_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(start) = rest.find("<!--") {
        out.push_str(&rest[..start]);
        match rest[start + 4..].find("-->") {
            Some(end) => rest = &rest[start + 4 + end + 3..],
            None => rest = "",
        }
    }
    out.push_str(rest);
    out
}

/// One paragraph's inline markup removed and its whitespace collapsed to single spaces.
pub fn plain(text: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    inline(&chars, &mut out);
    collapse(&out)
}

/// Runs of whitespace as one space, none at the ends.
pub fn collapse(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn inline(chars: &[char], out: &mut String) {
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        match c {
            // An escaped character is the character itself, never markup.
            '\\' if chars.get(i + 1).is_some_and(|n| n.is_ascii_punctuation()) => {
                out.push(chars[i + 1]);
                i += 2;
            }
            // An image (`![description](address)`) reads as its description, a link as its text.
            '!' | '[' => {
                let open = if c == '!' { i + 1 } else { i };
                match link(chars, open) {
                    Some((label, next)) => {
                        inline(label, out);
                        i = next;
                    }
                    None => {
                        out.push(c);
                        i += 1;
                    }
                }
            }
            '<' => match tag_end(chars, i) {
                Some((inner, next)) => {
                    // An autolink keeps its address (it is all the text there is); an HTML tag goes, leaving a
                    // space so that the words either side stay apart.
                    let inner: String = inner.iter().collect();
                    if inner.contains("://") || inner.starts_with("mailto:") {
                        out.push_str(inner.trim_start_matches("mailto:"));
                    } else {
                        out.push(' ');
                    }
                    i = next;
                }
                None => {
                    out.push(c);
                    i += 1;
                }
            },
            '*' | '`' => i += 1,
            '~' if chars.get(i + 1) == Some(&'~') => i += 2,
            // `_` is emphasis only at a word's edge: `snake_case` keeps it.
            '_' => {
                let before = i > 0 && chars[i - 1].is_alphanumeric();
                let after = chars.get(i + 1).is_some_and(|n| n.is_alphanumeric());
                if before && after {
                    out.push('_');
                }
                i += 1;
            }
            _ => {
                out.push(c);
                i += 1;
            }
        }
    }
}

/// A link or image starting at the `[` at `open`: its label and the index after it (after `(address)`,
/// `[reference]`, or the label alone). `None` when the bracket is not closed.
fn link(chars: &[char], open: usize) -> Option<(&[char], usize)> {
    let close = matching(chars, open, '[', ']')?;
    let label = &chars[open + 1..close];
    let next = match chars.get(close + 1) {
        Some('(') => matching(chars, close + 1, '(', ')').map_or(close + 1, |end| end + 1),
        Some('[') => matching(chars, close + 1, '[', ']').map_or(close + 1, |end| end + 1),
        _ => close + 1,
    };
    Some((label, next))
}

/// The index of the bracket that closes the one at `open`, counting nested pairs.
fn matching(chars: &[char], open: usize, left: char, right: char) -> Option<usize> {
    if chars.get(open) != Some(&left) {
        return None;
    }
    let mut depth = 0usize;
    let mut i = open;
    while i < chars.len() {
        let c = chars[i];
        if c == '\\' {
            i += 2;
            continue;
        }
        if c == left {
            depth += 1;
        } else if c == right {
            depth = depth.saturating_sub(1);
            if depth == 0 {
                return Some(i);
            }
        }
        i += 1;
    }
    None
}

/// An HTML tag or autolink at the `<` at `open` (`<br>`, `</b>`, `<https://x>`): what is inside and the index
/// after `>`. A `<` that starts no tag (`a < b`) is `None` and stays text.
fn tag_end(chars: &[char], open: usize) -> Option<(&[char], usize)> {
    let first = *chars.get(open + 1)?;
    if !(first.is_ascii_alphabetic() || first == '/') {
        return None;
    }
    let close = chars[open + 1..].iter().position(|&c| c == '>')? + open + 1;
    let inner = &chars[open + 1..close];
    if inner.iter().any(|c| *c == '<' || *c == '\n') {
        return None;
    }
    Some((inner, close + 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emphasis_and_code_marks_are_removed_and_their_words_kept() {
        assert_eq!(
            plain("Say **stop** or *be quiet*, or run `make run` ~~now~~."),
            "Say stop or be quiet, or run make run now."
        );
    }

    #[test]
    fn a_link_keeps_its_text_and_loses_its_address() {
        assert_eq!(
            plain("See [the brain](docs/brain.md) and [Whisper][asr]."),
            "See the brain and Whisper."
        );
        assert_eq!(
            plain("![a smiling face](face.png) Hello"),
            "a smiling face Hello"
        );
    }

    #[test]
    fn stray_brackets_and_exclamations_stay_text() {
        assert_eq!(plain("Hi! ] [ ok ![ x"), "Hi! ] [ ok ![ x");
    }

    #[test]
    fn html_tags_go_and_comments_are_stripped_across_lines() {
        assert_eq!(plain("one<br>two <b>three</b>"), "one two three");
        assert_eq!(strip_comments("a <!-- hidden\nnote --> b"), "a  b");
        assert_eq!(plain("a < b and c > d"), "a < b and c > d");
    }

    #[test]
    fn underscores_inside_words_stay_and_escapes_are_literal() {
        assert_eq!(
            plain("set _echo_window_ms_ \\*not bold\\*"),
            "set echo_window_ms *not bold*"
        );
    }
}
