//! One sentence, or one part of a sentence, as the voice spoke it: samples, mouth shapes and phonemes on the
//! samples' clock.

use crate::viseme::Viseme;

/// One sentence spoken by the voice.
#[derive(Debug, Clone, Default)]
pub(crate) struct Sentence {
    pub pcm: Vec<i16>,
    /// Viseme cues, in samples from the sentence's start.
    pub cues: Vec<(u64, Viseme)>,
    /// Every phoneme with its start in samples.
    pub phonemes: Vec<(u64, char)>,
    /// Phonemes without an id in the voice, or without a mouth shape.
    pub unknown: Vec<char>,
}
