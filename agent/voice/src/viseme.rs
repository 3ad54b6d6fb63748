//! The viseme set (the 15 Oculus/Meta visemes) and the mapping from espeak-ng's IPA phoneme names to it.
//!
//! The mapping works on IPA rather than on espeak-ng's per-language phoneme mnemonics, so one table serves
//! English, Italian and every other language espeak-ng speaks. docs/voice.md lists it in full.

use std::fmt;

/// A mouth shape. The order and names are those of the Oculus Lipsync viseme set, so index `i` here is blend
/// shape `viseme_<name>` in avatars made for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Viseme {
    /// Silence, mouth at rest.
    Sil,
    /// p, b, m: lips pressed together.
    PP,
    /// f, v: lower lip against upper teeth.
    FF,
    /// θ, ð: tongue between the teeth.
    TH,
    /// t, d: tongue tip on the ridge behind the teeth.
    DD,
    /// k, g, ŋ, h: tongue back raised, jaw half open.
    Kk,
    /// tʃ, dʒ, ʃ, ʒ: lips pushed forward and rounded, teeth close.
    CH,
    /// s, z, ts, dz: teeth close, lips spread.
    SS,
    /// n, l, ɲ, ʎ: tongue tip up, mouth slightly open.
    Nn,
    /// r, ɹ: lips slightly rounded.
    RR,
    /// a, ɑ, æ, ʌ: jaw open wide.
    Aa,
    /// e, ɛ, ə: jaw half open, lips relaxed.
    E,
    /// i, ɪ, j: lips spread, jaw nearly closed.
    I,
    /// o, ɔ, ɒ: lips rounded, jaw half open.
    O,
    /// u, ʊ, w: lips rounded and pushed forward.
    U,
}

impl Viseme {
    /// All visemes in Oculus order.
    pub const ALL: [Viseme; 15] = [
        Viseme::Sil,
        Viseme::PP,
        Viseme::FF,
        Viseme::TH,
        Viseme::DD,
        Viseme::Kk,
        Viseme::CH,
        Viseme::SS,
        Viseme::Nn,
        Viseme::RR,
        Viseme::Aa,
        Viseme::E,
        Viseme::I,
        Viseme::O,
        Viseme::U,
    ];

    /// The name used on the wire (`sil`, `PP`, ..., `U`): the Oculus viseme names as the browser link
    /// (docs/browser-link.md) spells them, with the Oculus table's `ih`, `oh`, `ou` written `I`, `O`, `U` as in
    /// the `viseme_I`, `viseme_O`, `viseme_U` blend shapes.
    pub fn name(self) -> &'static str {
        match self {
            Viseme::Sil => "sil",
            Viseme::PP => "PP",
            Viseme::FF => "FF",
            Viseme::TH => "TH",
            Viseme::DD => "DD",
            Viseme::Kk => "kk",
            Viseme::CH => "CH",
            Viseme::SS => "SS",
            Viseme::Nn => "nn",
            Viseme::RR => "RR",
            Viseme::Aa => "aa",
            Viseme::E => "E",
            Viseme::I => "I",
            Viseme::O => "O",
            Viseme::U => "U",
        }
    }

    /// Looks a viseme up by its wire name, also accepting the Oculus table's spellings `ih`, `oh`, `ou`.
    pub fn from_name(name: &str) -> Option<Viseme> {
        match name {
            "ih" => Some(Viseme::I),
            "oh" => Some(Viseme::O),
            "ou" => Some(Viseme::U),
            _ => Viseme::ALL.into_iter().find(|v| v.name() == name),
        }
    }

    /// Position in the Oculus list (0 = `sil` ... 14 = `U`).
    pub fn index(self) -> usize {
        self as usize
    }
}

impl fmt::Display for Viseme {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The mouth movement of one phoneme: a single shape, or for diphthongs a glide from one shape to another.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MouthShape {
    Single(Viseme),
    /// A diphthong such as `aɪ` or `oʊ`: the first shape for the first half of the phoneme, then the second.
    Glide(Viseme, Viseme),
}

/// Maps an espeak-ng IPA phoneme name (as carried by its phoneme events, stress marks included) to a mouth
/// shape. Returns `None` for a symbol the table does not know, so the caller can keep the previous shape.
pub fn mouth_shape(ipa: &str) -> Option<MouthShape> {
    // Stress, length and other modifiers (and combining diacritics such as nasalisation) do not change the
    // mouth shape.
    let core: String = ipa
        .chars()
        .filter(|&c| {
            !matches!(
                c,
                'ˈ' | 'ˌ' | 'ː' | 'ˑ' | '\'' | ',' | ':' | 'ʰ' | 'ʲ' | 'ʷ' | 'ˠ' | 'ˤ'
            ) && !('\u{0300}'..='\u{036F}').contains(&c)
        })
        .collect();
    if core.is_empty() || core.starts_with('_') || core.chars().all(|c| c.is_whitespace()) {
        return Some(MouthShape::Single(Viseme::Sil));
    }
    // Affricates are written as two letters but make one mouth shape.
    for (prefix, viseme) in [
        ("tʃ", Viseme::CH),
        ("dʒ", Viseme::CH),
        ("tɕ", Viseme::CH),
        ("dʑ", Viseme::CH),
        ("ts", Viseme::SS),
        ("dz", Viseme::SS),
    ] {
        if core.starts_with(prefix) {
            return Some(MouthShape::Single(viseme));
        }
    }
    let mut symbols = core.chars();
    let first = symbols.next()?;
    if let Some(viseme) = consonant(first) {
        return Some(MouthShape::Single(viseme));
    }
    let start = vowel(first)?;
    // A second vowel letter with a different shape makes a diphthong (`aɪ`, `aʊ`, `eɪ`, `oʊ`, `ɔɪ`, `ɪə`).
    let end = symbols.filter_map(vowel).find(|&v| v != start);
    Some(match end {
        Some(end) => MouthShape::Glide(start, end),
        None => MouthShape::Single(start),
    })
}

fn consonant(symbol: char) -> Option<Viseme> {
    Some(match symbol {
        'p' | 'b' | 'm' | 'ɓ' | 'ʙ' => Viseme::PP,
        'f' | 'v' | 'ɱ' | 'ʋ' | 'ɸ' | 'β' => Viseme::FF,
        'θ' | 'ð' => Viseme::TH,
        't' | 'd' | 'ɾ' | 'ʈ' | 'ɖ' | 'ɗ' | 'c' | 'ɟ' => Viseme::DD,
        // Velar, uvular and glottal sounds are made in the throat; the jaw stays half open like for k.
        'k' | 'g' | 'ɡ' | 'ŋ' | 'x' | 'ɣ' | 'χ' | 'q' | 'ɢ' | 'ɴ' | 'ħ' | 'ʕ' | 'h' | 'ɦ' | 'ʔ' => {
            Viseme::Kk
        }
        'ʃ' | 'ʒ' | 'ɕ' | 'ʑ' | 'ç' | 'ʝ' | 'ʧ' | 'ʤ' => Viseme::CH,
        's' | 'z' | 'ʂ' | 'ʐ' | 'ʦ' | 'ʣ' => Viseme::SS,
        'n' | 'l' | 'ɲ' | 'ʎ' | 'ɫ' | 'ɬ' | 'ɮ' | 'ɳ' | 'ɭ' | 'ʟ' | 'ɺ' | 'L' => {
            Viseme::Nn
        }
        'r' | 'ɹ' | 'ʁ' | 'ɻ' | 'ʀ' | 'ɽ' | 'ɚ' | 'ɝ' => Viseme::RR,
        // Glides take the shape of the vowel they come from.
        'j' => Viseme::I,
        'w' | 'ɥ' => Viseme::U,
        _ => return None,
    })
}

fn vowel(symbol: char) -> Option<Viseme> {
    Some(match symbol {
        'a' | 'ɑ' | 'ɐ' | 'æ' | 'ʌ' | 'ɶ' => Viseme::Aa,
        'e' | 'ɛ' | 'ə' | 'ɜ' | 'ɘ' | 'œ' | 'ø' | 'ɞ' => Viseme::E,
        'i' | 'ɪ' | 'y' | 'ʏ' | 'ɨ' | 'ᵻ' | 'ɯ' => Viseme::I,
        'o' | 'ɔ' | 'ɒ' | 'ɤ' | 'ɵ' => Viseme::O,
        'u' | 'ʊ' | 'ʉ' => Viseme::U,
        // An r-coloured vowel ends in an r shape (`ɑɹ`, `ɜː` with ɹ in American English).
        'ɚ' | 'ɝ' => Viseme::RR,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_in_oculus_order() {
        for (index, viseme) in Viseme::ALL.into_iter().enumerate() {
            assert_eq!(viseme.index(), index);
            assert_eq!(Viseme::from_name(viseme.name()), Some(viseme));
        }
        assert_eq!(Viseme::from_name("xx"), None);
        assert_eq!(Viseme::from_name("ou"), Some(Viseme::U));
        assert_eq!(Viseme::U.name(), "U");
    }

    #[test]
    fn consonants_vowels_and_affricates() {
        use MouthShape::Single;
        assert_eq!(mouth_shape("p"), Some(Single(Viseme::PP)));
        assert_eq!(mouth_shape("ð"), Some(Single(Viseme::TH)));
        assert_eq!(mouth_shape("tʃ"), Some(Single(Viseme::CH)));
        assert_eq!(mouth_shape("dz"), Some(Single(Viseme::SS)));
        assert_eq!(mouth_shape("ɲ"), Some(Single(Viseme::Nn)));
        assert_eq!(mouth_shape("ˈa"), Some(Single(Viseme::Aa)));
        assert_eq!(mouth_shape("ˌɔ"), Some(Single(Viseme::O)));
        assert_eq!(mouth_shape("iː"), Some(Single(Viseme::I)));
        assert_eq!(mouth_shape("_"), Some(Single(Viseme::Sil)));
        assert_eq!(mouth_shape(""), Some(Single(Viseme::Sil)));
    }

    #[test]
    fn diphthongs_glide() {
        assert_eq!(
            mouth_shape("ˈaɪ"),
            Some(MouthShape::Glide(Viseme::Aa, Viseme::I))
        );
        assert_eq!(
            mouth_shape("əʊ"),
            Some(MouthShape::Glide(Viseme::E, Viseme::U))
        );
        // Two letters with the same shape are not a glide.
        assert_eq!(
            mouth_shape("eɪ"),
            Some(MouthShape::Glide(Viseme::E, Viseme::I))
        );
        assert_eq!(mouth_shape("ɪi"), Some(MouthShape::Single(Viseme::I)));
    }

    #[test]
    fn unknown_symbols_are_reported() {
        assert_eq!(mouth_shape("☺"), None);
    }
}
