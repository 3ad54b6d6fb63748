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
    /// An open diphthong: where it started and the shape it ends in.
    open_glide: Option<(u64, Viseme)>,
    last_viseme: Option<Viseme>,
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
        for event in events {
            if let RawEventKind::Phoneme(ipa) = &event.kind {
                let sample = self.sentence_start + event.sample;
                self.marks.push(PhonemeMark {
                    sample,
                    ipa: ipa.clone(),
                    espeak_ms: event.audio_ms,
                });
                self.close_glide(sample);
                match mouth_shape(ipa) {
                    Some(MouthShape::Single(viseme)) => self.cue(sample, viseme),
                    Some(MouthShape::Glide(first, second)) => {
                        self.cue(sample, first);
                        self.open_glide = Some((sample, second));
                    }
                    None => self.unmapped.push(ipa.clone()),
                }
            }
        }
        if !pcm.is_empty() {
            self.held.push(SpeechChunk {
                sentence: self.sentence,
                sentence_start: self.sentence_start,
                start_sample: self.written,
                pcm: pcm.to_vec(),
                cues: Vec::new(),
                phonemes: Vec::new(),
            });
            self.written += pcm.len() as u64;
        }
        if self.open_glide.is_some() {
            Vec::new()
        } else {
            self.flush()
        }
    }

    /// Ends the current sentence: closes an open diphthong at the end of the audio, returns the mouth to rest
    /// there, and releases every held chunk.
    pub(crate) fn end_sentence(&mut self) -> Vec<SpeechChunk> {
        let end = self.written;
        self.close_glide(end);
        self.cue(end, Viseme::Sil);
        if self.held.is_empty() && (!self.cues.is_empty() || !self.marks.is_empty()) {
            // Cues with no audio after them still have to reach the consumer; an empty chunk carries them.
            self.held.push(SpeechChunk {
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

    fn close_glide(&mut self, next_start: u64) {
        if let Some((start, second)) = self.open_glide.take() {
            self.cue(start + next_start.saturating_sub(start) / 2, second);
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
                viseme: Viseme::Ih
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
