//! Offline transcription of a clip through the same path the satellite uses: resample, segment, transcribe.

use std::time::Duration;

use crate::resample::{ResampleError, StreamResampler};
use crate::segmenter::{RATE, SegmentEvent, Segmenter, SegmenterConfig, SegmenterError};
use crate::transcriber::{Outcome, TranscribeError, Transcriber};

/// Errors from an offline run.
#[derive(Debug, thiserror::Error)]
pub enum OfflineError {
    #[error(transparent)]
    Resample(#[from] ResampleError),
    #[error(transparent)]
    Segmenter(#[from] SegmenterError),
    #[error(transparent)]
    Transcribe(#[from] TranscribeError),
}

/// One utterance of a clip and what became of it.
#[derive(Debug, Clone, PartialEq)]
pub struct UtteranceResult {
    /// Start and end of speech in seconds from the clip start.
    pub start_s: f64,
    pub end_s: f64,
    pub outcome: Outcome,
}

impl UtteranceResult {
    /// The accepted text, if the filter kept it.
    pub fn text(&self) -> Option<&str> {
        match &self.outcome {
            Outcome::Speech(d) => Some(&d.text),
            Outcome::Rejected(..) => None,
        }
    }

    /// Inference time.
    pub fn processing(&self) -> Duration {
        match &self.outcome {
            Outcome::Speech(d) | Outcome::Rejected(_, d) => d.processing,
        }
    }
}

/// Splits a clip into utterances and transcribes each.
pub fn transcribe_clip(
    samples: &[f32],
    rate: u32,
    seg_cfg: SegmenterConfig,
    transcriber: &mut Transcriber,
) -> Result<Vec<UtteranceResult>, OfflineError> {
    let mut resampler = StreamResampler::new(rate, RATE)?;
    let mut audio = Vec::new();
    resampler.push(samples, &mut audio)?;
    resampler.flush(&mut audio)?;
    let mut segmenter = Segmenter::new(seg_cfg)?;
    let mut events = Vec::new();
    segmenter.push(&audio, &mut events);
    segmenter.finish(&mut events);
    let mut results = Vec::new();
    for ev in events {
        if let SegmentEvent::Ended(u) = ev {
            let outcome = transcriber.transcribe(&u.audio)?;
            results.push(UtteranceResult {
                start_s: u.start as f64 / f64::from(RATE),
                end_s: u.speech_end as f64 / f64::from(RATE),
                outcome,
            });
        }
    }
    Ok(results)
}

/// The accepted texts joined with spaces.
pub fn joined_text(results: &[UtteranceResult]) -> String {
    results
        .iter()
        .filter_map(UtteranceResult::text)
        .collect::<Vec<_>>()
        .join(" ")
}
