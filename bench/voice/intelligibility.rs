//! Intelligibility: every engine speaks the forty sentences, and our whisper path (the satellite's resampling,
//! segmentation and transcriber, `whisper_sat::offline`) with the base model writes down what it hears; the word
//! error rate against the text is the figure.

use std::path::Path;

use agent_voice::{SAMPLE_RATE, Synthesizer, VoiceSettings};
use anyhow::Context;
use whisper_sat::offline::{joined_text, transcribe_clip};
use whisper_sat::segmenter::SegmenterConfig;
use whisper_sat::transcriber::{Transcriber, TranscriberConfig};
use whisper_sat::wer::word_errors;

use crate::sentences::INTELLIGIBILITY;

/// Word errors of one engine over the set.
#[derive(Debug, Clone, Default)]
pub struct Heard {
    pub errors: usize,
    pub words: usize,
    /// (sentence, what whisper wrote) wherever a word was wrong.
    pub misheard: Vec<(String, String)>,
}

impl Heard {
    pub fn wer(&self) -> f64 {
        self.errors as f64 / self.words.max(1) as f64
    }
}

/// Loads the model (`models/ggml-base.bin`) with the satellite's settings, English, two threads.
pub fn transcriber(model: &Path) -> anyhow::Result<Transcriber> {
    Transcriber::load(
        model,
        TranscriberConfig {
            threads: 2,
            language: "en".into(),
            ..TranscriberConfig::default()
        },
    )
    .with_context(|| {
        format!(
            "loading {} (`make model-release MODEL=base`)",
            model.display()
        )
    })
}

/// What whisper writes for `pcm` (22050 Hz), through the satellite's path.
pub fn hear(transcriber: &mut Transcriber, pcm: &[i16]) -> anyhow::Result<String> {
    let samples: Vec<f32> = pcm.iter().map(|&s| f32::from(s) / 32768.0).collect();
    let results = transcribe_clip(
        &samples,
        SAMPLE_RATE,
        SegmenterConfig::default(),
        transcriber,
    )?;
    Ok(joined_text(&results))
}

/// Speaks every sentence with `voice` and scores what whisper hears.
pub fn score(
    engine: &Synthesizer,
    voice: &VoiceSettings,
    transcriber: &mut Transcriber,
) -> anyhow::Result<Heard> {
    let mut heard = Heard::default();
    for text in INTELLIGIBILITY {
        let recording = engine.speak(text, voice)?.collect_blocking()?;
        let written = hear(transcriber, &recording.pcm)?;
        let (errors, words) = word_errors(text, &written);
        heard.errors += errors;
        heard.words += words;
        if errors > 0 {
            heard.misheard.push((text.to_owned(), written));
        }
    }
    Ok(heard)
}
