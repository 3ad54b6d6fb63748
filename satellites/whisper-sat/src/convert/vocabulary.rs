//! Whisper's vocabulary as raw bytes: undoing GPT-2's byte-to-unicode mapping of `vocabulary.txt`.
//!
//! GPT-2 style BPE vocabularies store each token's bytes as printable Unicode characters: the 188 bytes that are
//! already printable map to themselves and the other 68 map to U+0100 onwards, in byte order. whisper.cpp expects the
//! raw bytes, so every token string is mapped back character by character.

use std::collections::HashMap;

/// Errors from decoding a vocabulary.
#[derive(Debug, thiserror::Error)]
pub enum VocabularyError {
    #[error("token {index} ({token:?}) contains {ch:?}, which is not in the byte-to-unicode table")]
    UnknownChar {
        index: usize,
        token: String,
        ch: char,
    },
    #[error("the vocabulary has no <|endoftext|> token")]
    NoEndOfText,
}

/// The 256-entry table byte -> printable character used by GPT-2's tokenizer.
pub fn byte_to_unicode() -> [char; 256] {
    let printable = |b: u32| {
        (u32::from(b'!')..=u32::from(b'~')).contains(&b)
            || (0xA1..=0xAC).contains(&b)
            || (0xAE..=0xFF).contains(&b)
    };
    let mut table = ['\0'; 256];
    let mut next_shifted = 256u32;
    for b in 0u32..256 {
        let code = if printable(b) {
            b
        } else {
            let c = next_shifted;
            next_shifted += 1;
            c
        };
        // Every code here is below U+0200, so it is a valid scalar value.
        table[b as usize] = char::from_u32(code).unwrap_or('\u{FFFD}');
    }
    table
}

/// The inverse table: printable character -> byte.
pub fn unicode_to_byte() -> HashMap<char, u8> {
    byte_to_unicode()
        .iter()
        .enumerate()
        .map(|(b, &c)| (c, b as u8))
        .collect()
}

/// Splits `vocabulary.txt` (one token per line, split on '\n' only because tokens may contain '\r') and returns the
/// raw bytes of every token below `<|endoftext|>`; whisper.cpp names the special tokens from that id on itself.
pub fn decode_vocabulary(text: &str) -> Result<Vec<Vec<u8>>, VocabularyError> {
    let tokens: Vec<&str> = text
        .strip_suffix('\n')
        .unwrap_or(text)
        .split('\n')
        .collect();
    let eot = tokens
        .iter()
        .position(|&t| t == "<|endoftext|>")
        .ok_or(VocabularyError::NoEndOfText)?;
    let table = unicode_to_byte();
    tokens[..eot]
        .iter()
        .enumerate()
        .map(|(index, token)| {
            token
                .chars()
                .map(|ch| {
                    table
                        .get(&ch)
                        .copied()
                        .ok_or_else(|| VocabularyError::UnknownChar {
                            index,
                            token: (*token).to_owned(),
                            ch,
                        })
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_is_a_bijection_onto_printable_characters() {
        let table = byte_to_unicode();
        let inverse = unicode_to_byte();
        assert_eq!(inverse.len(), 256);
        for b in 0..=255u8 {
            assert_eq!(inverse[&table[b as usize]], b);
            assert!(!table[b as usize].is_control() && !table[b as usize].is_whitespace());
        }
        // Known fixed points and shifts of GPT-2's table.
        assert_eq!(table[b'A' as usize], 'A');
        assert_eq!(table[b' ' as usize], '\u{120}'); // 'Ġ', the space marker of BPE tokens
        assert_eq!(table[b'\n' as usize], '\u{10A}'); // 'Ċ'
        assert_eq!(table[0], '\u{100}');
    }

    #[test]
    fn round_trips_arbitrary_bytes() {
        let table = byte_to_unicode();
        let bytes: Vec<u8> = "¿Qué tal? 日本\r\n\t".bytes().chain(0..=255).collect();
        let encoded: String = bytes.iter().map(|&b| table[b as usize]).collect();
        let vocab = format!("{encoded}\nĠthe\n<|endoftext|>\n<|startoftranscript|>\n");
        let decoded = decode_vocabulary(&vocab).expect("valid vocabulary");
        assert_eq!(decoded.len(), 2);
        assert_eq!(decoded[0], bytes);
        assert_eq!(decoded[1], b" the");
    }

    #[test]
    fn rejects_characters_outside_the_table_and_missing_end_of_text() {
        assert!(matches!(
            decode_vocabulary("a\nb\n"),
            Err(VocabularyError::NoEndOfText)
        ));
        assert!(matches!(
            decode_vocabulary("ok\nnot ascii space\n<|endoftext|>\n"),
            Err(VocabularyError::UnknownChar { index: 1, .. })
        ));
    }
}
