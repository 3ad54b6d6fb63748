//! The voice's network on ONNX Runtime (crate `ort`, loading the shared library `make model-voice` provisions):
//! phoneme ids and scales in, audio and each id's length in frames out.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use ort::environment::Environment;
use ort::session::Session;
use ort::session::builder::GraphOptimizationLevel;
use ort::value::Tensor;

use crate::error::VoiceError;

/// The output with the audio, and the one `scripts/voice/add_durations.py` adds: frames per input id.
const AUDIO: &str = "output";
const DURATIONS: &str = "/Ceil_output_0";

/// ONNX Runtime is loaded once per process, from the first library path asked for.
static RUNTIME: OnceLock<Mutex<Option<(PathBuf, Environment)>>> = OnceLock::new();

fn environment(library: &Path) -> Result<Environment, VoiceError> {
    let slot = RUNTIME.get_or_init(|| Mutex::new(None));
    let mut slot = slot
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some((loaded, env)) = slot.as_ref() {
        if loaded != library {
            return Err(VoiceError::Piper(format!(
                "ONNX Runtime is already loaded from {} in this process; {} cannot be loaded too",
                loaded.display(),
                library.display()
            )));
        }
        return Ok(env.clone());
    }
    let env = ort::init_from(library)
        .map_err(|e| {
            VoiceError::Piper(format!(
                "loading ONNX Runtime from {}: {e}",
                library.display()
            ))
        })?
        .with_name("agent-voice")
        .build()
        .map_err(|e| VoiceError::Piper(format!("starting ONNX Runtime: {e}")))?;
    *slot = Some((library.to_path_buf(), env.clone()));
    Ok(env)
}

/// A loaded voice network.
#[derive(Debug)]
pub(crate) struct Network {
    session: Session,
}

/// What one run of the network made.
#[derive(Debug, Clone)]
pub(crate) struct Output {
    /// Audio in [-1, 1] (not normalised).
    pub audio: Vec<f32>,
    /// Frames per input id.
    pub frames: Vec<f32>,
}

impl Network {
    /// Loads ONNX Runtime from `library` (once per process) and the voice from `model`, which must have the
    /// durations output.
    pub(crate) fn load(
        library: &Path,
        model: &Path,
        threads: usize,
    ) -> Result<Network, VoiceError> {
        let env = environment(library)?;
        let failed = |e: &dyn std::fmt::Display| {
            VoiceError::Piper(format!("loading {}: {e}", model.display()))
        };
        let session = Session::builder(&env)
            .map_err(|e| failed(&e))?
            .with_optimization_level(GraphOptimizationLevel::All)
            .map_err(|e| failed(&e))?
            .with_intra_threads(threads)
            .map_err(|e| failed(&e))?
            .with_inter_threads(1)
            .map_err(|e| failed(&e))?
            // Helpers sleep instead of spinning while they wait for work: a spinning helper took a busy core from
            // whisper-sat and the page (each run two to three times slower), a sleeping one only runs where a core
            // is idle, and ONNX Runtime takes back the work it has not started (docs/voice.md, "Threads").
            .with_intra_op_spinning(false)
            .map_err(|e| failed(&e))?
            .commit_from_file(model)
            .map_err(|e| failed(&e))?;
        let outputs: Vec<&str> = session.outputs().iter().map(|o| o.name()).collect();
        if !outputs.contains(&AUDIO) || !outputs.contains(&DURATIONS) {
            return Err(VoiceError::Piper(format!(
                "{} has outputs {outputs:?}, not {AUDIO:?} and {DURATIONS:?}: use the voice with durations that \
                 `make model-voice` derives (*.durations.onnx)",
                model.display()
            )));
        }
        Ok(Network { session })
    }

    /// Runs the network on one sentence's ids with `[noise_scale, length_scale, noise_w]`.
    pub(crate) fn run(&mut self, ids: &[i64], scales: [f32; 3]) -> Result<Output, VoiceError> {
        let failed = |e: &dyn std::fmt::Display| VoiceError::Piper(format!("inference: {e}"));
        let count = i64::try_from(ids.len()).map_err(|e| failed(&e))?;
        let input =
            Tensor::from_array((vec![1i64, count], ids.to_vec())).map_err(|e| failed(&e))?;
        let lengths = Tensor::from_array((vec![1i64], vec![count])).map_err(|e| failed(&e))?;
        let scales = Tensor::from_array((vec![3i64], scales.to_vec())).map_err(|e| failed(&e))?;
        let outputs = self
            .session
            .run(ort::inputs![
                "input" => input,
                "input_lengths" => lengths,
                "scales" => scales,
            ])
            .map_err(|e| failed(&e))?;
        let (_, audio) = outputs[AUDIO]
            .try_extract_tensor::<f32>()
            .map_err(|e| failed(&e))?;
        let (_, frames) = outputs[DURATIONS]
            .try_extract_tensor::<f32>()
            .map_err(|e| failed(&e))?;
        if frames.len() != ids.len() {
            return Err(VoiceError::Piper(format!(
                "{} durations for {} ids",
                frames.len(),
                ids.len()
            )));
        }
        Ok(Output {
            audio: audio.to_vec(),
            frames: frames.to_vec(),
        })
    }
}
