//! Errors of the speech synthesiser, one variant per thing a caller can act on.

use std::path::PathBuf;

/// Everything that can go wrong between a text and its PCM.
#[derive(Debug, thiserror::Error)]
pub enum VoiceError {
    /// No directory with espeak-ng's compiled data (`phontab`, dictionaries) was found.
    #[error(
        "espeak-ng data not found (looked in {searched:?}); install the Debian package `espeak-ng-data` \
         or set ESPEAK_DATA_PATH / the `data_path` option to a directory containing `phontab`"
    )]
    DataNotFound { searched: Vec<PathBuf> },

    /// espeak-ng refused to start with the data it was given.
    #[error("espeak-ng failed to initialise with data in {path}: {message}")]
    Init { path: PathBuf, message: String },

    /// espeak-ng keeps its state in C globals, so only one engine can exist in a process at a time.
    #[error(
        "an espeak-ng engine is already running in this process; share its `Synthesizer` handle"
    )]
    EngineBusy,

    /// The engine thread has ended (after a panic or because it was shut down).
    #[error("the speech engine thread has stopped")]
    EngineStopped,

    /// The request queue of the engine is full; the caller should cancel something or retry later.
    #[error("the speech engine queue is full ({capacity} utterances waiting)")]
    QueueFull { capacity: usize },

    /// espeak-ng does not know the requested voice or language.
    #[error("unknown espeak-ng voice {voice:?}: {message}")]
    VoiceNotFound { voice: String, message: String },

    /// A voice setting is outside the range espeak-ng accepts.
    #[error("invalid voice setting {name} = {value}: {reason}")]
    InvalidSetting {
        name: &'static str,
        value: String,
        reason: String,
    },

    /// The text cannot be passed to espeak-ng (it contains a NUL character).
    #[error("text cannot be synthesised: {0}")]
    InvalidText(String),

    /// espeak-ng reported an error while synthesising.
    #[error("espeak-ng synthesis failed: {0}")]
    Synthesis(String),

    /// A model file (the Piper voice, ONNX Runtime) is missing, damaged or unknown.
    #[error(
        "{what} {path}: {problem} (config/models.sha256 expects {expected}); run `make model-voice` to provision it"
    )]
    ModelFile {
        what: &'static str,
        path: PathBuf,
        problem: String,
        expected: String,
    },

    /// The Piper voice could not be loaded or run (its configuration, ONNX Runtime, the network).
    #[error("Piper voice: {0}")]
    Piper(String),

    /// A request asked for the Piper engine but this synthesizer was started without a Piper voice.
    #[error("no Piper voice is loaded (start the synthesizer with a `piper` configuration)")]
    PiperUnavailable,
}
