//! `whisper-sat transcribe FILE.wav`: offline transcription through the satellite's segmentation and filter.

use std::path::PathBuf;

use anyhow::Context;
use whisper_sat::offline::{UtteranceResult, joined_text, transcribe_clip};
use whisper_sat::segmenter::SegmenterConfig;
use whisper_sat::transcriber::{AudioContext, Outcome, Transcriber, TranscriberConfig};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// WAV file (16-bit or float, any rate, mono or stereo).
    file: PathBuf,
    /// ggml model file (default: models/ggml-tiny.en.bin in the repository, or WHISPER_MODEL).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Inference threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// End-of-speech hangover in milliseconds.
    #[arg(long, default_value_t = SegmenterConfig::default().hangover_ms)]
    hangover_ms: u32,
    /// Run the full 30 s encoder window instead of fitting it to the utterance.
    #[arg(long)]
    full_window: bool,
    /// Transcribe the whole file as one utterance (no VAD).
    #[arg(long)]
    whole: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let model = args
        .model
        .unwrap_or_else(whisper_sat::model_path::default_model);
    let clip = whisper_sat::wav::read_mono(&args.file)?;
    let cfg = TranscriberConfig {
        threads: args.threads,
        audio_context: if args.full_window {
            AudioContext::Full
        } else {
            AudioContext::Fit
        },
        ..TranscriberConfig::default()
    };
    let mut transcriber = Transcriber::load(&model, cfg)?;
    if args.whole {
        let audio = whisper_sat::resample::resample_clip(&clip.samples, clip.rate, 16_000)?;
        let d = transcriber.decode(&audio)?;
        println!("{}", d.text);
        eprintln!(
            "{:.2} s audio in {} ms (rtf {:.3}), no-speech {:.2}, mean logprob {:.2}",
            clip.seconds(),
            d.processing.as_millis(),
            d.processing.as_secs_f64() / clip.seconds(),
            d.no_speech_prob,
            d.avg_logprob
        );
        return Ok(());
    }
    let seg = SegmenterConfig {
        hangover_ms: args.hangover_ms,
        ..SegmenterConfig::default()
    };
    let results = transcribe_clip(&clip.samples, clip.rate, seg, &mut transcriber)
        .with_context(|| format!("transcribing {}", args.file.display()))?;
    for r in &results {
        print_result(r);
    }
    println!("{}", joined_text(&results));
    Ok(())
}

fn print_result(r: &UtteranceResult) {
    let ms = r.processing().as_millis();
    match &r.outcome {
        Outcome::Speech(d) => {
            eprintln!("[{:6.2} - {:6.2}] ({ms} ms) {}", r.start_s, r.end_s, d.text)
        }
        Outcome::Rejected(why, d) => {
            eprintln!(
                "[{:6.2} - {:6.2}] ({ms} ms) rejected {why:?}: {:?}",
                r.start_s, r.end_s, d.text
            )
        }
    }
}
