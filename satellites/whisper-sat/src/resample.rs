//! Sample-rate conversion to Whisper's 16 kHz with rubato's FFT resampler, for whole clips and for streams.
//!
//! The stream resampler removes rubato's fixed output delay, so output sample `k` lines up with input time
//! `k / rate_out`: utterance boundaries found on the 16 kHz stream map straight back onto the hub's audio clock.

use rubato::{FftFixedInOut, Resampler};

/// Errors from building or running a resampler.
#[derive(Debug, thiserror::Error)]
pub enum ResampleError {
    #[error("cannot resample {from} Hz to {to} Hz: {reason}")]
    Construction { from: u32, to: u32, reason: String },
    #[error("resampling failed: {0}")]
    Process(String),
}

/// A mono resampler that accepts input in pieces of any length.
pub struct StreamResampler {
    /// `None` when input and output rates are equal: samples pass through untouched.
    inner: Option<FftFixedInOut<f32>>,
    rate_in: u32,
    rate_out: u32,
    pending: Vec<f32>,
    /// Leading output samples still to drop (the resampler's delay).
    to_skip: usize,
    consumed_in: u64,
    produced_out: u64,
}

impl std::fmt::Debug for StreamResampler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StreamResampler")
            .field("rate_in", &self.rate_in)
            .field("rate_out", &self.rate_out)
            .field("pending", &self.pending.len())
            .finish()
    }
}

impl StreamResampler {
    /// A resampler from `rate_in` to `rate_out`. Chunks are one "period" of the two rates (441 in -> 320 out for
    /// 22050 -> 16000 Hz, i.e. 20 ms), which matches the hub's audio chunks and keeps latency at one chunk.
    pub fn new(rate_in: u32, rate_out: u32) -> Result<Self, ResampleError> {
        let inner = if rate_in == rate_out {
            None
        } else {
            let r = FftFixedInOut::<f32>::new(rate_in as usize, rate_out as usize, 1, 1).map_err(
                |e| ResampleError::Construction {
                    from: rate_in,
                    to: rate_out,
                    reason: e.to_string(),
                },
            )?;
            Some(r)
        };
        let to_skip = inner.as_ref().map_or(0, Resampler::output_delay);
        Ok(Self {
            inner,
            rate_in,
            rate_out,
            pending: Vec::new(),
            to_skip,
            consumed_in: 0,
            produced_out: 0,
        })
    }

    /// Input rate in Hz.
    pub fn rate_in(&self) -> u32 {
        self.rate_in
    }

    /// Feeds samples; appends every output sample that is complete to `out`.
    pub fn push(&mut self, input: &[f32], out: &mut Vec<f32>) -> Result<(), ResampleError> {
        self.consumed_in += input.len() as u64;
        let Some(r) = self.inner.as_mut() else {
            out.extend_from_slice(input);
            self.produced_out += input.len() as u64;
            return Ok(());
        };
        self.pending.extend_from_slice(input);
        let mut start = 0;
        loop {
            let need = r.input_frames_next();
            if self.pending.len() - start < need {
                break;
            }
            let chunk = &self.pending[start..start + need];
            let res = r
                .process(&[chunk], None)
                .map_err(|e| ResampleError::Process(e.to_string()))?;
            start += need;
            let produced = res.into_iter().next().unwrap_or_default();
            let skip = self.to_skip.min(produced.len());
            self.to_skip -= skip;
            self.produced_out += (produced.len() - skip) as u64;
            out.extend_from_slice(&produced[skip..]);
        }
        self.pending.drain(..start);
        Ok(())
    }

    /// Ends the stream: pushes silence through so the last input samples come out, then trims the output to the
    /// length the input duration implies.
    pub fn flush(&mut self, out: &mut Vec<f32>) -> Result<(), ResampleError> {
        let Some(r) = self.inner.as_ref() else {
            return Ok(());
        };
        let expected =
            (self.consumed_in * u64::from(self.rate_out)).div_ceil(u64::from(self.rate_in));
        let pad = vec![0.0; r.input_frames_next()];
        let consumed = self.consumed_in;
        let mut tail = Vec::new();
        while self.produced_out < expected {
            self.push(&pad, &mut tail)?;
        }
        // The padding is not input: forget it, and drop whatever it produced past the input's duration.
        self.consumed_in = consumed;
        let over = (self.produced_out - expected) as usize;
        tail.truncate(tail.len().saturating_sub(over));
        self.produced_out = expected;
        out.extend_from_slice(&tail);
        Ok(())
    }
}

/// Resamples a whole mono clip.
pub fn resample_clip(
    input: &[f32],
    rate_in: u32,
    rate_out: u32,
) -> Result<Vec<f32>, ResampleError> {
    let mut r = StreamResampler::new(rate_in, rate_out)?;
    let mut out = Vec::with_capacity(input.len() * rate_out as usize / rate_in.max(1) as usize + 1);
    r.push(input, &mut out)?;
    r.flush(&mut out)?;
    Ok(out)
}

/// Converts s16le PCM bytes to f32 samples in [-1, 1).
pub fn pcm_s16le_to_f32(bytes: &[u8], out: &mut Vec<f32>) {
    out.extend(
        bytes
            .chunks_exact(2)
            .map(|c| f32::from(i16::from_le_bytes([c[0], c[1]])) / 32768.0),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sine(freq: f32, rate: u32, n: usize) -> Vec<f32> {
        (0..n)
            .map(|i| (2.0 * std::f32::consts::PI * freq * i as f32 / rate as f32).sin() * 0.5)
            .collect()
    }

    #[test]
    fn stream_and_clip_resampling_agree_and_keep_the_duration() -> Result<(), ResampleError> {
        let input = sine(440.0, 22_050, 22_050);
        let whole = resample_clip(&input, 22_050, 16_000)?;
        assert_eq!(whole.len(), 16_000);
        let mut r = StreamResampler::new(22_050, 16_000)?;
        let mut pieces = Vec::new();
        for chunk in input.chunks(137) {
            r.push(chunk, &mut pieces)?;
        }
        r.flush(&mut pieces)?;
        assert_eq!(pieces.len(), whole.len());
        assert!(pieces.iter().zip(&whole).all(|(a, b)| (a - b).abs() < 1e-4));
        Ok(())
    }

    #[test]
    fn delay_is_removed_so_a_tone_stays_in_phase() -> Result<(), ResampleError> {
        let input = sine(300.0, 22_050, 11_025);
        let out = resample_clip(&input, 22_050, 16_000)?;
        let reference = sine(300.0, 16_000, out.len());
        // Away from the edges, the resampled tone matches a tone generated directly at 16 kHz.
        let err = out[1000..7000]
            .iter()
            .zip(&reference[1000..7000])
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        // A one-sample misalignment at 300 Hz would leave an error of 0.5 * 2 * pi * 300 / 16000 = 0.059.
        assert!(err < 0.04, "max error {err}");
        Ok(())
    }

    #[test]
    fn equal_rates_pass_through() -> Result<(), ResampleError> {
        let input = sine(100.0, 16_000, 500);
        assert_eq!(resample_clip(&input, 16_000, 16_000)?, input);
        Ok(())
    }

    #[test]
    fn pcm_conversion_scales_to_unit_range() {
        let mut out = Vec::new();
        pcm_s16le_to_f32(&[0x00, 0x80, 0xff, 0x7f, 0, 0], &mut out);
        assert_eq!(out, vec![-1.0, 32767.0 / 32768.0, 0.0]);
    }
}
