//! `whisper-sat convert`: CTranslate2 model directory -> ggml file.

use std::path::PathBuf;

use anyhow::Context;

use super::progress::Bars;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Directory with CTranslate2's model.bin and vocabulary.txt.
    #[arg(long)]
    ct2_dir: PathBuf,
    /// Output ggml file.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut bars = Bars::default();
    let summary =
        whisper_sat::convert::convert(&args.ct2_dir, &args.out, &mut bars).with_context(|| {
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
