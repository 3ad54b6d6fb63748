//! `whisper-sat transcribe FILE.wav`: offline transcription through the satellite's segmentation and filter.

use std::path::PathBuf;

use anyhow::Context;
use whisper_sat::offline::{UtteranceResult, joined_text, transcribe_clip};
use whisper_sat::recognition::RecognitionArgs;
use whisper_sat::transcriber::{Outcome, Transcriber};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// WAV file (16-bit or float, any rate, mono or stereo).
    file: PathBuf,
    #[command(flatten)]
    recognition: RecognitionArgs,
    /// Transcribe the whole file as one utterance (no VAD).
    #[arg(long)]
    whole: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let model = args.recognition.model();
    let clip = whisper_sat::wav::read_mono(&args.file)?;
    let cfg = args.recognition.transcriber();
    let mut transcriber = Transcriber::load(&model, cfg)?;
    // An offline transcription on a machine whose satellites are running takes its share of the cores too.
    if let Some(share) = args.recognition.core_share()? {
        transcriber.share_cores(share);
    }
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
    let seg = args.recognition.segmenter();
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
