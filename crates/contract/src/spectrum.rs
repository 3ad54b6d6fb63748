//! The spectra on `Agent.audio.fft`: how the audio_fft module computes them and what the page assumes when it reads
//! them (the welcome's `fft`, docs/browser-link.md). In one place so that the module, the browser link and the page
//! cannot drift apart.

/// Samples per FFT.
pub const FFT_SIZE: usize = 1024;
/// Magnitudes per spectrum: bins 0..FFT_SIZE/2 (the Nyquist bin is left out so the count is a round 512).
pub const BINS: usize = FFT_SIZE / 2;
/// The analysed audio's sample rate: the microphone's, as the page sends it on `Agent.audio`.
pub const RATE: u32 = 22050;
/// The payload: [`BINS`] magnitudes as f32 little-endian values.
pub const FORMAT: &str = "f32le";
/// The window applied before each FFT.
pub const WINDOW: &str = "hann";
/// How magnitudes are scaled: a full-scale sine gives 1.0 in its bin (the page turns them into dB).
pub const SCALE: &str = "linear, full-scale sine = 1.0";
/// The largest hop between two spectra: one FFT size, no overlap (the smallest is 1).
pub const MAX_HOP: usize = FFT_SIZE;
