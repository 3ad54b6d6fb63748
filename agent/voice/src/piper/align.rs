//! The network's durations made into times: every input id lasts a whole number of frames (`hop` samples each,
//! 256 for Piper voices), and the frames add up to exactly the audio it made, so the running sum of the frames is
//! each phoneme's start on the PCM's own sample clock. The phonemes' mouth shapes then become viseme cues.

use super::phonemes::Owner;
use crate::viseme::{MouthShape, Viseme, mouth_shape};

/// Where one phoneme (its pad included) lies in the sentence's audio.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Span {
    /// `None` for the start and end markers.
    pub phoneme: Option<char>,
    /// Samples from the start of the sentence.
    pub start: u64,
    pub end: u64,
}

/// Groups the ids' frames by owner: one span per phoneme, plus the start and end markers.
pub(crate) fn spans(phonemes: &[char], owners: &[Owner], frames: &[f32], hop: u64) -> Vec<Span> {
    let mut spans: Vec<Span> = Vec::new();
    let mut last_owner = None;
    let mut at = 0u64;
    for (owner, &count) in owners.iter().zip(frames) {
        // Frames are whole numbers (the graph's Ceil); a negative or NaN value would be a broken graph, counted 0.
        let samples = if count.is_finite() && count > 0.0 {
            count.round() as u64 * hop
        } else {
            0
        };
        if last_owner == Some(*owner) {
            if let Some(span) = spans.last_mut() {
                span.end += samples;
            }
        } else {
            let phoneme = match owner {
                Owner::Phoneme(index) => phonemes.get(*index).copied(),
                Owner::Start | Owner::End => None,
            };
            spans.push(Span {
                phoneme,
                start: at,
                end: at + samples,
            });
            last_owner = Some(*owner);
        }
        at += samples;
    }
    spans
}

/// What a phoneme character does to the mouth.
fn shape_of(phoneme: char) -> Option<Result<Viseme, ()>> {
    match phoneme {
        // Punctuation is a pause in Piper's voices: the mouth rests.
        '.' | '?' | '!' | ',' | ':' | ';' => Some(Ok(Viseme::Sil)),
        // Word gaps run the words together, and stress, length and other modifiers do not move the mouth.
        ' ' | 'ˈ' | 'ˌ' | 'ː' | 'ˑ' | 'ʰ' | 'ʲ' | 'ʷ' | 'ˠ' | 'ˤ' | '-' | '\'' => None,
        c if ('\u{0300}'..='\u{036F}').contains(&c) => None,
        c => match mouth_shape(c.encode_utf8(&mut [0; 4])) {
            Some(MouthShape::Single(viseme) | MouthShape::Glide(viseme, _)) => Some(Ok(viseme)),
            None => Some(Err(())),
        },
    }
}

/// The viseme cues of a sentence (positions in samples from its start), with repeated shapes merged, the mouth at
/// rest from the start and from the end marker on; phonemes without a shape are returned too.
pub(crate) fn cues(spans: &[Span]) -> (Vec<(u64, Viseme)>, Vec<char>) {
    let mut cues: Vec<(u64, Viseme)> = Vec::new();
    let mut unmapped = Vec::new();
    let push = |cues: &mut Vec<(u64, Viseme)>, at: u64, viseme: Viseme| {
        if cues.last().map(|c| c.1) != Some(viseme) {
            cues.push((at, viseme));
        }
    };
    // A stress mark comes before its vowel, and the network gives it frames of that vowel's sound: the vowel's
    // shape starts where its stress mark does.
    let mut stressed_from = None;
    for span in spans {
        match span.phoneme {
            None => push(&mut cues, span.start, Viseme::Sil),
            Some('ˈ' | 'ˌ') => {
                stressed_from.get_or_insert(span.start);
            }
            Some(phoneme) => match shape_of(phoneme) {
                Some(Ok(viseme)) => push(
                    &mut cues,
                    stressed_from.take().unwrap_or(span.start),
                    viseme,
                ),
                Some(Err(())) => unmapped.push(phoneme),
                None => {}
            },
        }
        if !matches!(span.phoneme, Some('ˈ' | 'ˌ')) {
            stressed_from = None;
        }
    }
    (cues, unmapped)
}

/// Energy windows of 5 ms at 22050 Hz.
const WINDOW: usize = 110;
/// A window is sound when its RMS is above this share of the sentence's loud level (its 95th percentile window):
/// about -26 dB.
const SOUND_SHARE: f64 = 0.05;

/// Moves each return to rest back to where the sound before it fades out. The network gives a vowel before a pause
/// all its frames, and the last tens of milliseconds of them are the sound dying away; a mouth that stays open
/// through them closes visibly after the voice has stopped. Only rests after an open shape move, never before that
/// shape's own cue, and never later than the durations put them.
pub(crate) fn close_at_silence(cues: &mut [(u64, Viseme)], pcm: &[i16]) {
    let energy: Vec<f64> = pcm
        .chunks(WINDOW)
        .map(|w| (w.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>() / w.len() as f64).sqrt())
        .collect();
    if energy.is_empty() {
        return;
    }
    let mut sorted = energy.clone();
    sorted.sort_by(f64::total_cmp);
    let threshold = sorted[sorted.len() * 95 / 100] * SOUND_SHARE;
    for index in 1..cues.len() {
        let (open_at, open) = cues[index - 1];
        let (rest_at, rest) = cues[index];
        if rest != Viseme::Sil || open == Viseme::Sil {
            continue;
        }
        let first = open_at as usize / WINDOW + 1;
        let last = (rest_at as usize / WINDOW).min(energy.len());
        if first >= last {
            continue;
        }
        // The window after the last one with sound, between the open shape's start and the rest.
        let fade = (first..last)
            .rev()
            .find(|&w| energy[w] > threshold)
            .map_or(first, |w| w + 1);
        let at = (fade * WINDOW) as u64;
        if at < rest_at {
            cues[index].0 = at;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_add_up_per_phoneme_on_the_sample_clock() {
        let phonemes = ['h', 'ˈ', 'a', '.'];
        let owners = [
            Owner::Start,
            Owner::Start,
            Owner::Phoneme(0),
            Owner::Phoneme(0),
            Owner::Phoneme(1),
            Owner::Phoneme(1),
            Owner::Phoneme(2),
            Owner::Phoneme(2),
            Owner::Phoneme(3),
            Owner::Phoneme(3),
            Owner::End,
        ];
        let frames = [2.0, 1.0, 3.0, 0.0, 0.0, 1.0, 5.0, 1.0, 4.0, 0.0, 2.0];
        let spans = spans(&phonemes, &owners, &frames, 256);
        let starts: Vec<u64> = spans.iter().map(|s| s.start).collect();
        assert_eq!(starts, vec![0, 768, 1536, 1792, 3328, 4352]);
        assert_eq!(spans.last().map(|s| s.end), Some(19 * 256));
        let (cues, unmapped) = cues(&spans);
        // The stressed vowel's shape starts at its stress mark; the full stop rests the mouth, and the end marker
        // keeps it at rest.
        assert_eq!(
            cues,
            vec![
                (0, Viseme::Sil),
                (768, Viseme::Kk),
                (1536, Viseme::Aa),
                (3328, Viseme::Sil)
            ]
        );
        assert!(unmapped.is_empty());
    }

    #[test]
    fn a_rest_moves_back_to_where_the_sound_fades() {
        // Sound until sample 2200 (20 windows), then near silence; the durations put the rest at 3300.
        let mut pcm = vec![8000i16; 2200];
        pcm.extend(vec![20i16; 2200]);
        let mut cues = vec![(0, Viseme::Aa), (3300, Viseme::Sil), (3850, Viseme::E)];
        close_at_silence(&mut cues, &pcm);
        assert_eq!(
            cues,
            vec![(0, Viseme::Aa), (2200, Viseme::Sil), (3850, Viseme::E)]
        );
        // A rest over sound stays where it is.
        let loud = vec![8000i16; 4400];
        let mut cues = vec![(0, Viseme::Aa), (3300, Viseme::Sil)];
        close_at_silence(&mut cues, &loud);
        assert_eq!(cues, vec![(0, Viseme::Aa), (3300, Viseme::Sil)]);
    }

    #[test]
    fn unknown_phonemes_keep_the_shape_and_are_reported() {
        let spans = [
            Span {
                phoneme: None,
                start: 0,
                end: 10,
            },
            Span {
                phoneme: Some('ʘ'),
                start: 10,
                end: 20,
            },
        ];
        let (cues, unmapped) = cues(&spans);
        assert_eq!(cues, vec![(0, Viseme::Sil)]);
        assert_eq!(unmapped, vec!['ʘ']);
    }
}
