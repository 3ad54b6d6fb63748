//! `whisper-sat convert`: CTranslate2 model directory -> ggml file.

use std::path::PathBuf;

use anyhow::Context;

use whisper_sat::convert::Weights;

use super::progress::Bars;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Directory with CTranslate2's model.bin and vocabulary.txt.
    #[arg(long)]
    ct2_dir: PathBuf,
    /// Output ggml file.
    #[arg(long)]
    out: PathBuf,
    /// How to store the weight matrices: `f16` (the packages' precision) or `q8_0` (8-bit blocks, what
    /// faster-whisper's int8 runs; smaller and faster: docs/asr.md).
    #[arg(long, value_enum, default_value_t = WeightsArg::F16)]
    weights: WeightsArg,
}

/// The `--weights` choices.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum WeightsArg {
    F16,
    #[value(name = "q8_0")]
    Q8_0,
}

impl From<WeightsArg> for Weights {
    fn from(w: WeightsArg) -> Weights {
        match w {
            WeightsArg::F16 => Weights::F16,
            WeightsArg::Q8_0 => Weights::Q8_0,
        }
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut bars = Bars::default();
    let summary =
        whisper_sat::convert::convert(&args.ct2_dir, &args.out, args.weights.into(), &mut bars)
            .with_context(|| {
                format!(
                    "converting {} to {}",
                    args.ct2_dir.display(),
                    args.out.display()
                )
            })?;
    drop(bars);
    let hp = summary.hparams;
    println!(
        "wrote {} ({} tensors, {} tokens, {:.1} MB): {} audio layers x {} state, {} text layers, {} mels",
        args.out.display(),
        summary.tensors,
        summary.vocabulary,
        summary.bytes as f64 / 1e6,
        hp.n_audio_layer,
        hp.n_audio_state,
        hp.n_text_layer,
        hp.n_mels
    );
    Ok(())
}
