//! Turning espeak-ng's PCM buffers and phoneme events into speech chunks that carry their own viseme cues.
//!
//! Positions are absolute sample indices from the start of the utterance (the PCM clock): each sentence is a
//! separate espeak-ng call counting from zero, so the builder adds the samples of the sentences before it.
//! A cue says "from this sample on, show this viseme"; it holds until the next cue.
//!
//! Diphthongs switch shape half way through, which is only known once the next phoneme starts. Chunks are
//! therefore held back while a diphthong is open, so that every cue travels in the chunk whose samples it
//! falls in. espeak-ng generates hundreds of times faster than real time, so holding a few 20 ms buffers costs
//! well under a millisecond.

use crate::espeak::{RawEvent, RawEventKind};
use crate::viseme::{MouthShape, Viseme, mouth_shape};

/// "From `sample` on, the mouth shows `viseme`."
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VisemeCue {
    /// Absolute sample index in the utterance's PCM.
    pub sample: u64,
    pub viseme: Viseme,
}

impl VisemeCue {
    /// The cue time in milliseconds on the PCM clock.
    pub fn at_ms(&self, sample_rate: u32) -> f64 {
        samples_to_ms(self.sample, sample_rate)
    }
}

/// A phoneme as espeak-ng announced it, kept for diagnostics and for checking the cues against the source.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PhonemeMark {
    /// Absolute sample index in the utterance's PCM.
    pub sample: u64,
    /// IPA spelling from espeak-ng, stress marks included.
    pub ipa: String,
    /// espeak-ng's own millisecond position of the event, counted from the start of its sentence.
    pub espeak_ms: u64,
}

/// A piece of speech: PCM plus the cues and phonemes that start inside it.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeechChunk {
    /// Index of the sentence in the utterance.
    pub sentence: usize,
    /// Absolute sample index of the first sample of the sentence this chunk belongs to.
    pub sentence_start: u64,
    /// Absolute sample index of `pcm[0]`.
    pub start_sample: u64,
    /// Mono signed 16-bit PCM at the engine's sample rate.
    pub pcm: Vec<i16>,
    /// Cues with `start_sample <= sample < start_sample + pcm.len()` (the last chunk of a sentence may also
    /// carry a cue exactly at its end).
    pub cues: Vec<VisemeCue>,
    pub phonemes: Vec<PhonemeMark>,
    /// Which run of the Piper network within the sentence made this chunk: 0, and 1 for the rest of a first
    /// sentence spoken in two parts (always 0 for espeak-ng).
    pub part: u32,
}

impl SpeechChunk {
    /// Absolute sample index just past this chunk.
    pub fn end_sample(&self) -> u64 {
        self.start_sample + self.pcm.len() as u64
    }
}

/// Converts a sample count at `sample_rate` to milliseconds.
pub fn samples_to_ms(samples: u64, sample_rate: u32) -> f64 {
    samples as f64 * 1000.0 / f64::from(sample_rate.max(1))
}

/// A phoneme whose mouth shape depends on what follows it, waiting for the next phoneme event.
#[derive(Debug, Clone, Copy)]
enum OpenPhoneme {
    /// A diphthong that switches to `second` half way to the next phoneme.
    Glide { start: u64, second: Viseme },
    /// A phoneme without an IPA spelling. espeak-ng reports pauses this way, but also short linking sounds
    /// inside words (the Italian schwa before a tapped r, the English linking `;`); only the audio tells them
    /// apart, so it becomes a rest only if the samples up to the next phoneme are quiet.
    Unspelled { start: u64 },
}

/// Quiet means an RMS below this share of the loudest chunk so far...
const QUIET_SHARE: f64 = 0.1;
/// ...capped at this absolute RMS (about -46 dBFS), so that a loud voice does not make soft speech "quiet".
const QUIET_CEILING: f64 = 160.0;

/// Builds chunks for one utterance, one espeak-ng buffer at a time.
#[derive(Debug, Default)]
pub(crate) struct TimelineBuilder {
    sentence: usize,
    sentence_start: u64,
    /// Absolute samples received so far.
    written: u64,
    held: Vec<SpeechChunk>,
    /// Cues and marks not yet given to a chunk, in time order.
    cues: Vec<VisemeCue>,
    marks: Vec<PhonemeMark>,
    open: Option<OpenPhoneme>,
    last_viseme: Option<Viseme>,
    /// RMS of the loudest chunk so far, the reference for "quiet".
    loudest_rms: f64,
    /// Phoneme names the viseme table did not know (they keep the previous shape).
    pub unmapped: Vec<String>,
}

impl TimelineBuilder {
    /// Starts sentence `index`; its sample positions count from the samples written so far.
    pub(crate) fn begin_sentence(&mut self, index: usize) {
        self.sentence = index;
        self.sentence_start = self.written;
    }

    /// Samples written so far in the utterance.
    pub(crate) fn written(&self) -> u64 {
        self.written
    }

    /// Takes one espeak-ng buffer and returns the chunks that are complete.
    pub(crate) fn push(&mut self, pcm: &[i16], events: &[RawEvent]) -> Vec<SpeechChunk> {
        // The buffer goes in first: the events inside it may need its samples to be decided.
        if !pcm.is_empty() {
            self.loudest_rms = self.loudest_rms.max(rms(pcm));
            self.held.push(SpeechChunk {
                part: 0,
                sentence: self.sentence,
                sentence_start: self.sentence_start,
                start_sample: self.written,
                pcm: pcm.to_vec(),
                cues: Vec::new(),
                phonemes: Vec::new(),
            });
            self.written += pcm.len() as u64;
        }
        for event in events {
            if let RawEventKind::Phoneme(ipa) = &event.kind {
                let sample = self.sentence_start + event.sample;
                self.marks.push(PhonemeMark {
                    sample,
                    ipa: ipa.clone(),
                    espeak_ms: event.audio_ms,
                });
                self.close_open(sample);
                self.start_phoneme(sample, ipa);
            }
        }
        if self.open.is_some() {
            Vec::new()
        } else {
            self.flush()
        }
    }

    /// Ends the current sentence: decides an open phoneme against the end of the audio, returns the mouth to
    /// rest there, and releases every held chunk.
    pub(crate) fn end_sentence(&mut self) -> Vec<SpeechChunk> {
        let end = self.written;
        self.close_open(end);
        self.cue(end, Viseme::Sil);
        if self.held.is_empty() && (!self.cues.is_empty() || !self.marks.is_empty()) {
            // Cues with no audio after them still have to reach the consumer; an empty chunk carries them.
            self.held.push(SpeechChunk {
                part: 0,
                sentence: self.sentence,
                sentence_start: self.sentence_start,
                start_sample: end,
                pcm: Vec::new(),
                cues: Vec::new(),
                phonemes: Vec::new(),
            });
        }
        self.flush()
    }

    fn start_phoneme(&mut self, sample: u64, ipa: &str) {
        if ipa.trim().is_empty() {
            self.open = Some(OpenPhoneme::Unspelled { start: sample });
            return;
        }
        match mouth_shape(ipa) {
            Some(MouthShape::Single(viseme)) => self.cue(sample, viseme),
            Some(MouthShape::Glide(first, second)) => {
                self.cue(sample, first);
                self.open = Some(OpenPhoneme::Glide {
                    start: sample,
                    second,
                });
            }
            None => self.unmapped.push(ipa.to_owned()),
        }
    }

    /// Decides the open phoneme now that the next one starts at `next_start`.
    fn close_open(&mut self, next_start: u64) {
        match self.open.take() {
            Some(OpenPhoneme::Glide { start, second }) => {
                self.cue(start + next_start.saturating_sub(start) / 2, second);
            }
            Some(OpenPhoneme::Unspelled { start }) if next_start > start => {
                // At the very start nothing loud has been heard yet; only near-digital silence counts then.
                let threshold = (self.loudest_rms * QUIET_SHARE).clamp(1.0, QUIET_CEILING);
                if self.held_rms(start, next_start) < threshold {
                    self.cue(start, Viseme::Sil);
                }
            }
            Some(OpenPhoneme::Unspelled { .. }) | None => {}
        }
    }

    /// RMS of the held samples in `from..to` (absolute positions).
    fn held_rms(&self, from: u64, to: u64) -> f64 {
        let (mut sum, mut count) = (0.0, 0u64);
        for chunk in &self.held {
            let lo = from.max(chunk.start_sample);
            let hi = to.min(chunk.end_sample());
            if lo < hi {
                let slice = &chunk.pcm
                    [(lo - chunk.start_sample) as usize..(hi - chunk.start_sample) as usize];
                sum += slice.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>();
                count += hi - lo;
            }
        }
        if count == 0 {
            0.0
        } else {
            (sum / count as f64).sqrt()
        }
    }

    /// Adds a cue unless the mouth already has that shape.
    fn cue(&mut self, sample: u64, viseme: Viseme) {
        if self.last_viseme != Some(viseme) {
            self.cues.push(VisemeCue { sample, viseme });
            self.last_viseme = Some(viseme);
        }
    }

    /// Hands every held chunk out with the cues and marks that fall inside it.
    fn flush(&mut self) -> Vec<SpeechChunk> {
        let mut chunks = std::mem::take(&mut self.held);
        let count = chunks.len();
        for (position, chunk) in chunks.iter_mut().enumerate() {
            let is_last = position + 1 == count;
            let end = chunk.end_sample();
            let inside = |sample: u64| is_last || sample < end;
            let cue_count = self.cues.iter().take_while(|c| inside(c.sample)).count();
            chunk.cues = self.cues.drain(..cue_count).collect();
            let mark_count = self.marks.iter().take_while(|m| inside(m.sample)).count();
            chunk.phonemes = self.marks.drain(..mark_count).collect();
        }
        chunks
    }
}

fn rms(pcm: &[i16]) -> f64 {
    if pcm.is_empty() {
        return 0.0;
    }
    (pcm.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>() / pcm.len() as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn phoneme(ipa: &str, sample: u64) -> RawEvent {
        RawEvent {
            kind: RawEventKind::Phoneme(ipa.into()),
            sample,
            audio_ms: sample * 1000 / 22050,
        }
    }

    #[test]
    fn cues_travel_with_their_chunk_and_sentences_add_up() {
        let mut builder = TimelineBuilder::default();
        builder.begin_sentence(0);
        let first = builder.push(&[0; 100], &[phoneme("h", 0), phoneme("ə", 60)]);
        assert_eq!(first.len(), 1);
        assert_eq!(first[0].cues.len(), 2);
        let tail = builder.end_sentence();
        assert_eq!(tail.len(), 1, "an empty chunk carries the closing rest cue");
        assert_eq!(
            tail[0].cues,
            vec![VisemeCue {
                sample: 100,
                viseme: Viseme::Sil
            }]
        );

        builder.begin_sentence(1);
        let second = builder.push(&[0; 50], &[phoneme("p", 10)]);
        assert_eq!(second[0].start_sample, 100);
        assert_eq!(second[0].sentence_start, 100);
        assert_eq!(
            second[0].cues,
            vec![VisemeCue {
                sample: 110,
                viseme: Viseme::PP
            }]
        );
    }

    #[test]
    fn diphthong_holds_chunks_until_the_next_phoneme() {
        let mut builder = TimelineBuilder::default();
        builder.begin_sentence(0);
        assert!(builder.push(&[0; 100], &[phoneme("ˈaɪ", 20)]).is_empty());
        assert!(builder.push(&[0; 100], &[]).is_empty());
        let released = builder.push(&[0; 100], &[phoneme("s", 220)]);
        assert_eq!(released.len(), 3);
        assert_eq!(
            released[0].cues,
            vec![VisemeCue {
                sample: 20,
                viseme: Viseme::Aa
            }]
        );
        assert_eq!(
            released[1].cues,
            vec![VisemeCue {
                sample: 120,
                viseme: Viseme::I
            }]
        );
        assert_eq!(
            released[2].cues,
            vec![VisemeCue {
                sample: 220,
                viseme: Viseme::SS
            }]
        );
    }

    #[test]
    fn unspelled_phonemes_rest_only_over_quiet_audio() {
        let mut builder = TimelineBuilder::default();
        builder.begin_sentence(0);
        let loud = [3000i16, -3000].repeat(100);
        // A loud vowel, then an unspelled phoneme over loud audio (a linking sound): no rest.
        let mut chunks = builder.push(&loud, &[phoneme("a", 0), phoneme("", 100)]);
        chunks.extend(builder.push(&loud, &[phoneme("n", 250)]));
        // Then an unspelled phoneme over silence (a pause): the mouth rests.
        chunks.extend(builder.push(&[0; 200], &[phoneme("", 400)]));
        chunks.extend(builder.push(&loud, &[phoneme("a", 600)]));
        let cues: Vec<(u64, Viseme)> = chunks
            .iter()
            .flat_map(|c| c.cues.iter().map(|q| (q.sample, q.viseme)))
            .collect();
        assert_eq!(
            cues,
            vec![
                (0, Viseme::Aa),
                (250, Viseme::Nn),
                (400, Viseme::Sil),
                (600, Viseme::Aa)
            ]
        );
    }

    #[test]
    fn repeated_shapes_are_merged_and_unknown_phonemes_recorded() {
        let mut builder = TimelineBuilder::default();
        builder.begin_sentence(0);
        let chunks = builder.push(
            &[0; 100],
            &[phoneme("p", 0), phoneme("b", 30), phoneme("☺", 60)],
        );
        assert_eq!(chunks[0].cues.len(), 1);
        assert_eq!(chunks[0].phonemes.len(), 3);
        assert_eq!(builder.unmapped, vec!["☺".to_string()]);
    }
}
