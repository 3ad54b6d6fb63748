//! Splitting a reply into sentences, the unit the engine synthesises (and can cancel between) one at a time.

/// Splits `text` into trimmed, non-empty sentences.
///
/// A sentence ends after `.`, `!`, `?`, `;`, `…` (with any closing quotes or brackets right after them) when
/// whitespace or the end of the text follows, and at every line break. Requiring whitespace keeps numbers such
/// as `3.5` and names such as `example.com` whole; abbreviations such as `e.g. this` are split, which only
/// costs a slightly longer pause.
pub fn split_sentences(text: &str) -> Vec<&str> {
    let mut sentences = Vec::new();
    let mut start = 0;
    let mut chars = text.char_indices().peekable();
    while let Some((index, c)) = chars.next() {
        let end = if c == '\n' {
            Some(index)
        } else if matches!(c, '.' | '!' | '?' | ';' | '…') {
            let mut end = index + c.len_utf8();
            // Keep repeated marks and closing punctuation ("?!", "...", ".)") with the sentence.
            while let Some(&(next_index, next)) = chars.peek() {
                if matches!(
                    next,
                    '.' | '!' | '?' | '…' | '"' | '\'' | ')' | ']' | '»' | '”' | '’'
                ) {
                    end = next_index + next.len_utf8();
                    chars.next();
                } else {
                    break;
                }
            }
            match chars.peek() {
                None => Some(end),
                Some(&(_, next)) if next.is_whitespace() => Some(end),
                _ => None,
            }
        } else {
            None
        };
        if let Some(end) = end {
            push_trimmed(&mut sentences, &text[start..end]);
            start = end;
        }
    }
    push_trimmed(&mut sentences, &text[start..]);
    sentences
}

fn push_trimmed<'a>(sentences: &mut Vec<&'a str>, piece: &'a str) {
    let piece = piece.trim();
    if !piece.is_empty() {
        sentences.push(piece);
    }
}

#[cfg(test)]
mod tests {
    use super::split_sentences;

    #[test]
    fn splits_on_terminal_punctuation_and_lines() {
        assert_eq!(
            split_sentences("Hello there! It is 3.5 degrees.  What now?\nBye"),
            vec!["Hello there!", "It is 3.5 degrees.", "What now?", "Bye"]
        );
    }

    #[test]
    fn keeps_closing_marks_and_ignores_blank_pieces() {
        assert_eq!(
            split_sentences("Really?!\" he said...  \n\n ok"),
            vec!["Really?!\"", "he said...", "ok"]
        );
        assert!(split_sentences("  \n ").is_empty());
        assert_eq!(split_sentences("no terminator"), vec!["no terminator"]);
    }

    #[test]
    fn italian_text() {
        assert_eq!(
            split_sentences("Ciao! Come stai? Bene."),
            vec!["Ciao!", "Come stai?", "Bene."]
        );
    }
}
