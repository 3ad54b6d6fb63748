//! WAV loading for `pub-wav`: any PCM or float WAV to s16le mono 22050 Hz.

use std::path::Path;

use anyhow::{Context, bail};

/// The agent's audio rate.
pub const RATE: u32 = 22050;

/// Reads a WAV file, mixes it down to mono and resamples it to 22050 Hz.
pub fn load_as_22050_mono(path: &Path) -> anyhow::Result<Vec<i16>> {
    let reader =
        hound::WavReader::open(path).with_context(|| format!("reading {}", path.display()))?;
    let spec = reader.spec();
    if spec.channels == 0 || spec.sample_rate == 0 {
        bail!("{}: WAV header has no channels or no rate", path.display());
    }
    let samples: Vec<f32> = match spec.sample_format {
        hound::SampleFormat::Float => reader.into_samples::<f32>().collect::<Result<_, _>>()?,
        hound::SampleFormat::Int => {
            let scale = 1.0 / (1u64 << (spec.bits_per_sample.clamp(1, 32) - 1)) as f32;
            reader
                .into_samples::<i32>()
                .map(|s| s.map(|v| v as f32 * scale))
                .collect::<Result<_, _>>()?
        }
    };
    let channels = spec.channels as usize;
    let mono: Vec<f32> = samples
        .chunks(channels)
        .map(|frame| frame.iter().sum::<f32>() / channels as f32)
        .collect();
    let resampled = if spec.sample_rate == RATE {
        mono
    } else {
        resample(&mono, spec.sample_rate, RATE)
    };
    Ok(resampled
        .into_iter()
        .map(|v| (v * 32768.0).round().clamp(-32768.0, 32767.0) as i16)
        .collect())
}

/// Band-limited resampling by windowed-sinc interpolation (Hann window,
/// 32 taps): clean enough that speech recognisers see no aliasing artefacts.
pub fn resample(input: &[f32], from: u32, to: u32) -> Vec<f32> {
    const HALF_TAPS: i64 = 16;
    let ratio = f64::from(to) / f64::from(from);
    // Below the lower Nyquist frequency, to avoid aliasing when downsampling.
    let cutoff = ratio.min(1.0) * 0.97;
    let out_len = (input.len() as f64 * ratio).round() as usize;
    let mut out = Vec::with_capacity(out_len);
    for n in 0..out_len {
        let t = n as f64 / ratio;
        let centre = t.floor() as i64;
        let mut acc = 0.0f64;
        let mut norm = 0.0f64;
        for k in (centre - HALF_TAPS + 1)..=(centre + HALF_TAPS) {
            let x = t - k as f64;
            let window = 0.5 + 0.5 * (std::f64::consts::PI * x / HALF_TAPS as f64).cos();
            let arg = std::f64::consts::PI * cutoff * x;
            let sinc = if arg.abs() < 1e-9 {
                1.0
            } else {
                arg.sin() / arg
            };
            let w = cutoff * sinc * window;
            norm += w;
            if k >= 0 && (k as usize) < input.len() {
                acc += f64::from(input[k as usize]) * w;
            }
        }
        out.push(if norm.abs() > 1e-9 {
            (acc / norm) as f32
        } else {
            0.0
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resampling_keeps_a_tone_and_its_length() {
        let from = 16000;
        let tone: Vec<f32> = (0..16000)
            .map(|i| (2.0 * std::f32::consts::PI * 440.0 * i as f32 / from as f32).sin() * 0.5)
            .collect();
        let out = resample(&tone, from, RATE);
        assert_eq!(out.len(), 22050);
        // Compare with the ideal tone at the new rate, away from the edges.
        let err: f32 = (100..22000)
            .map(|i| {
                (out[i] - (2.0 * std::f32::consts::PI * 440.0 * i as f32 / RATE as f32).sin() * 0.5)
                    .abs()
            })
            .fold(0.0, f32::max);
        assert!(err < 0.01, "max error {err}");
    }
}
