//! The microphone spectrum: Hann-windowed 1024-point FFTs (rustfft) of the s16le audio, as linear magnitudes; the
//! sizes are the contract's (`agent_contract::spectrum`), which the page reads them by.
//!
//! Magnitudes are scaled so that a full-scale sine gives 1.0 in its bin: |X[k]| * 2 / sum(window). The page turns
//! them into dB; detectors can use them as they are.

use std::sync::Arc;

use agent_contract::spectrum::{BINS, FFT_SIZE};
use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

/// Turns a stream of samples into one spectrum every `hop` samples.
pub struct SpectrumAnalyser {
    fft: Arc<dyn Fft<f32>>,
    window: Vec<f32>,
    norm: f32,
    hop: usize,
    pending: Vec<f32>,
    buf: Vec<Complex<f32>>,
    scratch: Vec<Complex<f32>>,
}

impl std::fmt::Debug for SpectrumAnalyser {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SpectrumAnalyser")
            .field("hop", &self.hop)
            .field("pending", &self.pending.len())
            .finish()
    }
}

impl SpectrumAnalyser {
    /// `hop` is clamped to 1..=FFT_SIZE (FFT_SIZE means no overlap).
    pub fn new(hop: usize) -> Self {
        let fft = FftPlanner::<f32>::new().plan_fft_forward(FFT_SIZE);
        let window: Vec<f32> = (0..FFT_SIZE)
            .map(|i| {
                let x = std::f32::consts::TAU * i as f32 / FFT_SIZE as f32;
                0.5 - 0.5 * x.cos()
            })
            .collect();
        let norm = 2.0 / window.iter().sum::<f32>();
        let scratch = vec![Complex::default(); fft.get_inplace_scratch_len()];
        SpectrumAnalyser {
            fft,
            window,
            norm,
            hop: hop.clamp(1, FFT_SIZE),
            pending: Vec::with_capacity(FFT_SIZE * 2),
            buf: vec![Complex::default(); FFT_SIZE],
            scratch,
        }
    }

    /// Adds s16le PCM bytes (a trailing odd byte is ignored) and calls `emit` with each spectrum that completes.
    pub fn push_pcm(&mut self, pcm: &[u8], mut emit: impl FnMut(&[f32])) {
        self.pending.extend(
            pcm.chunks_exact(2)
                .map(|b| f32::from(i16::from_le_bytes([b[0], b[1]])) / 32768.0),
        );
        let mut mags = [0f32; BINS];
        while self.pending.len() >= FFT_SIZE {
            for (slot, (s, w)) in self
                .buf
                .iter_mut()
                .zip(self.pending.iter().zip(&self.window))
            {
                *slot = Complex::new(s * w, 0.0);
            }
            self.fft
                .process_with_scratch(&mut self.buf, &mut self.scratch);
            for (m, c) in mags.iter_mut().zip(&self.buf) {
                *m = c.norm() * self.norm;
            }
            emit(&mags);
            self.pending.drain(..self.hop);
        }
    }
}

/// The spectrum as the `Agent.audio.fft` payload: f32 little-endian values.
pub fn to_le_bytes(mags: &[f32]) -> Vec<u8> {
    mags.iter().flat_map(|m| m.to_le_bytes()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tone(freq: f32, amplitude: f32, n: usize) -> Vec<u8> {
        (0..n)
            .flat_map(|i| {
                let v = amplitude * (std::f32::consts::TAU * freq * i as f32 / 22050.0).sin();
                ((v * 32767.0) as i16).to_le_bytes()
            })
            .collect()
    }

    #[test]
    fn a_tone_peaks_in_its_bin_with_calibrated_magnitude() {
        let mut a = SpectrumAnalyser::new(FFT_SIZE);
        let mut spectra = Vec::new();
        // Fed in 20 ms chunks, as the page sends them.
        for chunk in tone(1000.0, 0.5, 22050).chunks(882) {
            a.push_pcm(chunk, |m| spectra.push(m.to_vec()));
        }
        assert_eq!(spectra.len(), 22050 / FFT_SIZE);
        let s = &spectra[5];
        let peak = (0..BINS)
            .max_by(|&i, &j| s[i].total_cmp(&s[j]))
            .expect("bins");
        let peak_hz = peak as f32 * 22050.0 / FFT_SIZE as f32;
        assert!(
            (peak_hz - 1000.0).abs() < 22050.0 / FFT_SIZE as f32,
            "peak at {peak_hz} Hz"
        );
        // Between bins the Hann window loses up to ~1.4 dB; a 0.5 sine reads 0.42..0.5.
        assert!(s[peak] > 0.42 && s[peak] < 0.51, "magnitude {}", s[peak]);
        let far = s[peak + 20];
        assert!(far < s[peak] * 0.001, "leakage {far}");
    }

    #[test]
    fn hop_sets_the_overlap() {
        let mut a = SpectrumAnalyser::new(FFT_SIZE / 2);
        let mut n = 0;
        a.push_pcm(&tone(440.0, 0.1, FFT_SIZE * 4), |_| n += 1);
        assert_eq!(n, 7);
    }
}
