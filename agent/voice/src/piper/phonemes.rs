//! From espeak-ng's clauses to the network's input: the phoneme characters of a sentence (with the clauses'
//! punctuation, as Piper voices are trained) and their ids, each id remembering which phoneme it belongs to so
//! that the network's per-id durations become per-phoneme times.

use super::voice_file::{BOS, EOS, PAD, VoiceFile};

/// Punctuation that espeak-ng ends a clause at and that Piper voices have ids for.
const TERMINATORS: [char; 6] = ['.', '?', '!', ',', ':', ';'];

/// The phonemes of one sentence, one character each, from espeak-ng's clauses and the text each consumed.
pub(crate) fn sentence_phonemes<'a>(
    clauses: impl IntoIterator<Item = (&'a str, &'a str)>,
) -> Vec<char> {
    let mut phonemes = Vec::new();
    for (ipa, consumed) in clauses {
        let before = phonemes.len();
        phonemes.extend(without_language_flags(ipa).chars());
        if phonemes.len() == before && consumed.trim().is_empty() {
            continue;
        }
        let terminator = consumed
            .trim_end()
            .chars()
            .next_back()
            .filter(|c| TERMINATORS.contains(c));
        if let Some(terminator) = terminator {
            phonemes.push(terminator);
            // A clause inside a sentence: the next clause's words are separate ones.
            if matches!(terminator, ',' | ':' | ';') {
                phonemes.push(' ');
            }
        } else if phonemes.len() > before {
            phonemes.push(' ');
        }
    }
    while phonemes.last() == Some(&' ') {
        phonemes.pop();
    }
    phonemes
}

/// espeak-ng marks words it reads in another language with `(en)` ... `(it)`; they are not phonemes.
fn without_language_flags(ipa: &str) -> String {
    let mut out = String::with_capacity(ipa.len());
    let mut depth = 0usize;
    for c in ipa.chars() {
        match c {
            '(' => depth += 1,
            ')' if depth > 0 => depth -= 1,
            _ if depth == 0 => out.push(c),
            _ => {}
        }
    }
    out
}

/// Which part of the sentence an input id belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Owner {
    /// The sentence start marker and its pad.
    Start,
    /// Phoneme `i` of the sentence (its pad included).
    Phoneme(usize),
    /// The sentence end marker.
    End,
}

/// The network's input ids with the owner of each: `^ _ p1 _ p2 _ ... $`. Phonemes the voice has no id for are
/// left out (and returned, so the caller can report them).
pub(crate) fn to_ids(voice: &VoiceFile, phonemes: &[char]) -> (Vec<i64>, Vec<Owner>, Vec<char>) {
    let mut ids = Vec::with_capacity(phonemes.len() * 2 + 3);
    let mut owners = Vec::with_capacity(ids.capacity());
    let mut unknown = Vec::new();
    let push = |ids: &mut Vec<i64>, owners: &mut Vec<Owner>, marker: char, owner: Owner| {
        for &id in voice.ids(marker).unwrap_or_default() {
            ids.push(id);
            owners.push(owner);
        }
    };
    push(&mut ids, &mut owners, BOS, Owner::Start);
    push(&mut ids, &mut owners, PAD, Owner::Start);
    for (index, &phoneme) in phonemes.iter().enumerate() {
        if voice.ids(phoneme).is_none() {
            unknown.push(phoneme);
            continue;
        }
        push(&mut ids, &mut owners, phoneme, Owner::Phoneme(index));
        push(&mut ids, &mut owners, PAD, Owner::Phoneme(index));
    }
    push(&mut ids, &mut owners, EOS, Owner::End);
    (ids, owners, unknown)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clauses_keep_their_punctuation_and_lose_language_flags() {
        let phonemes = sentence_phonemes([
            ("həlˈoʊ", "Hello, "),
            ("(fr)bõʒˈuʁ(en) ðɛɹ", "bonjour there!"),
        ]);
        let text: String = phonemes.iter().collect();
        assert_eq!(text, "həlˈoʊ, bõʒˈuʁ ðɛɹ!");
        let plain: String = sentence_phonemes([("haɪ", "hi")]).iter().collect();
        assert_eq!(plain, "haɪ");
    }

    #[test]
    fn ids_wrap_every_phoneme_in_pads_and_remember_their_owner() {
        let voice = VoiceFile::parse(
            r#"{"audio":{"sample_rate":22050},"espeak":{"voice":"en-us"},
            "inference":{"noise_scale":0.667,"length_scale":1,"noise_w":0.8},
            "phoneme_id_map":{"_":[0],"^":[1],"$":[2],"a":[14],"b":[15]}}"#,
        )
        .expect("voice");
        let (ids, owners, unknown) = to_ids(&voice, &['b', 'ʘ', 'a']);
        assert_eq!(ids, vec![1, 0, 15, 0, 14, 0, 2]);
        assert_eq!(
            owners,
            vec![
                Owner::Start,
                Owner::Start,
                Owner::Phoneme(0),
                Owner::Phoneme(0),
                Owner::Phoneme(2),
                Owner::Phoneme(2),
                Owner::End
            ]
        );
        assert_eq!(unknown, vec!['ʘ']);
    }
}
