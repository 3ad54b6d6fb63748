//! One request spoken in the Piper voice on the engine thread: espeak-ng phonemises, the network speaks, and the
//! audio goes out in `chunk_ms` pieces carrying the cues that fall in them. The first sentence is spoken in two
//! runs when it has a natural break after a few words (the first part plays while the rest is synthesised, joined
//! without a gap or a click: `piper::join`), and a sentence spoken before with the same rate and volume comes from
//! the voice's cache without running the network.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use super::job::{Counters, Request, SpeechEvent};
use crate::error::VoiceError;
use crate::espeak::Espeak;
use crate::piper::{self, Key, PiperVoice, Sentence};
use crate::sentence::split_sentences;
use crate::timeline::{PhonemeMark, SpeechChunk, VisemeCue};
use crate::viseme::Viseme;

/// Where the utterance stands: samples written, the last shape given, phonemes the voice could not say.
struct Stream<'a> {
    request: &'a Request,
    chunk_samples: usize,
    rate: u32,
    written: u64,
    last_viseme: Option<Viseme>,
    unknown: Vec<char>,
}

/// Whether the utterance goes on after a step, or stopped (cancelled, or its consumer gone).
enum Step {
    Go,
    Stop,
}

/// Speaks one request with the Piper voice; returns the samples produced and whether it was cancelled.
/// Cancellation is checked before every run of the network and every chunk.
pub(super) fn speak_piper(
    espeak: &mut Espeak,
    piper: &mut PiperVoice,
    chunk_ms: u32,
    counters: &Counters,
    request: &Request,
) -> Result<(u64, bool), VoiceError> {
    if request.cancel.is_cancelled() {
        return Ok((0, true));
    }
    espeak.set_voice(&piper.file.espeak_voice)?;
    let rate = piper.file.sample_rate;
    let mut stream = Stream {
        request,
        chunk_samples: (u64::from(rate) * u64::from(chunk_ms) / 1000).max(1) as usize,
        rate,
        written: 0,
        last_viseme: None,
        unknown: Vec::new(),
    };
    // espeak-ng's default rate is the voice's natural pace; other rates stretch or squeeze the phonemes.
    let length = 175.0 / request.voice.rate_wpm as f32;
    let gain = request.voice.volume as f32 / 100.0;
    for (index, text) in split_sentences(&request.text).into_iter().enumerate() {
        if request.cancel.is_cancelled() {
            return Ok((stream.written, true));
        }
        let key = Key {
            text: text.to_owned(),
            length,
            gain,
        };
        let start = stream.written;
        if let Some(kept) = piper.cache.get(&key) {
            counters.piper_cache_hits.fetch_add(1, Ordering::Relaxed);
            if let Step::Stop = stream.send_part(index, start, &kept, 0, true) {
                return Ok((stream.written, true));
            }
        } else {
            // Only the first sentence is cut: the later ones are synthesised while the ones before them play.
            let parts: Vec<&str> = match (index, piper::first_break(text, piper.first_part_words)) {
                (0, Some((head, tail))) => vec![head, tail],
                _ => vec![text],
            };
            let count = parts.len();
            let mut whole = Sentence::default();
            let mut scale = None;
            for (position, part) in parts.into_iter().enumerate() {
                if request.cancel.is_cancelled() {
                    return Ok((stream.written, true));
                }
                let clauses = espeak.text_to_phonemes(part)?;
                counters.piper_runs.fetch_add(1, Ordering::Relaxed);
                let (mut spoken, used) = piper.speak(
                    clauses
                        .iter()
                        .map(|c| (c.ipa.as_str(), c.consumed.as_str())),
                    length,
                    gain,
                    scale,
                )?;
                scale = used;
                if position > 0 {
                    piper::start_part(&mut spoken, rate);
                }
                let last = position + 1 == count;
                if !last {
                    piper::end_part(&mut spoken, rate);
                }
                if let Step::Stop = stream.send_part(index, start, &spoken, position as u32, last) {
                    return Ok((stream.written, true));
                }
                piper::append(&mut whole, spoken);
            }
            piper.cache.put(key, Arc::new(whole));
        }
        let sentence_end = SpeechEvent::SentenceEnd {
            sentence: index,
            text: text.to_owned(),
            start_sample: start,
            end_sample: stream.written,
        };
        if request.out.blocking_send(sentence_end).is_err() {
            return Ok((stream.written, true));
        }
    }
    if !stream.unknown.is_empty() {
        tracing::debug!(
            unknown = ?stream.unknown,
            "phonemes the Piper voice has no id or mouth shape for"
        );
    }
    Ok((stream.written, request.cancel.is_cancelled()))
}

impl Stream<'_> {
    /// Sends one spoken part of sentence `index` (which started at `sentence_start`) in chunks; the last part of a
    /// sentence closes the mouth at its end.
    fn send_part(
        &mut self,
        index: usize,
        sentence_start: u64,
        spoken: &Sentence,
        part: u32,
        last: bool,
    ) -> Step {
        self.unknown.extend(spoken.unknown.iter().copied());
        let start = self.written;
        let end = start + spoken.pcm.len() as u64;
        let closing = last.then_some((end - start, Viseme::Sil));
        let mut cues: Vec<VisemeCue> = Vec::with_capacity(spoken.cues.len() + 1);
        for &(at, viseme) in spoken.cues.iter().chain(closing.iter()) {
            if self.last_viseme != Some(viseme) {
                cues.push(VisemeCue {
                    sample: start + at.min(end - start),
                    viseme,
                });
                self.last_viseme = Some(viseme);
            }
        }
        let mut marks: Vec<PhonemeMark> = spoken
            .phonemes
            .iter()
            .map(|&(at, phoneme)| PhonemeMark {
                sample: start + at,
                ipa: phoneme.to_string(),
                espeak_ms: (start + at - sentence_start) * 1000 / u64::from(self.rate.max(1)),
            })
            .collect();
        let mut pieces: Vec<&[i16]> = spoken.pcm.chunks(self.chunk_samples).collect();
        if pieces.is_empty() && !cues.is_empty() {
            pieces.push(&[]);
        }
        let count = pieces.len();
        for (position, piece) in pieces.into_iter().enumerate() {
            if self.request.cancel.is_cancelled() {
                return Step::Stop;
            }
            let chunk_start = self.written;
            let chunk_end = chunk_start + piece.len() as u64;
            let inside = |sample: u64| position + 1 == count || sample < chunk_end;
            let cue_count = cues.iter().take_while(|c| inside(c.sample)).count();
            let mark_count = marks.iter().take_while(|m| inside(m.sample)).count();
            let chunk = SpeechChunk {
                sentence: index,
                sentence_start,
                start_sample: chunk_start,
                pcm: piece.to_vec(),
                cues: cues.drain(..cue_count).collect(),
                phonemes: marks.drain(..mark_count).collect(),
                part,
            };
            if self
                .request
                .out
                .blocking_send(SpeechEvent::Chunk(chunk))
                .is_err()
            {
                return Step::Stop;
            }
            self.written = chunk_end;
        }
        Step::Go
    }
}
