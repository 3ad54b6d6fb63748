//! Reading WAV files as mono f32 samples.

use std::path::{Path, PathBuf};

/// Errors from reading a WAV file.
#[derive(Debug, thiserror::Error)]
pub enum WavError {
    #[error("{path}: {source}")]
    Read { path: PathBuf, source: hound::Error },
    #[error("{path}: unsupported sample format ({bits}-bit {format:?})")]
    Format {
        path: PathBuf,
        bits: u16,
        format: hound::SampleFormat,
    },
}

/// A decoded clip.
#[derive(Debug, Clone, PartialEq)]
pub struct Clip {
    pub rate: u32,
    pub samples: Vec<f32>,
}

impl Clip {
    /// Duration in seconds.
    pub fn seconds(&self) -> f64 {
        self.samples.len() as f64 / f64::from(self.rate.max(1))
    }
}

/// Reads 16-bit integer or 32-bit float WAV, averaging channels to mono.
pub fn read_mono(path: &Path) -> Result<Clip, WavError> {
    let err = |source| WavError::Read {
        path: path.to_path_buf(),
        source,
    };
    let mut reader = hound::WavReader::open(path).map_err(err)?;
    let spec = reader.spec();
    let channels = usize::from(spec.channels.max(1));
    let interleaved: Vec<f32> = match (spec.sample_format, spec.bits_per_sample) {
        (hound::SampleFormat::Int, 16) => reader
            .samples::<i16>()
            .map(|s| s.map(|v| f32::from(v) / 32768.0))
            .collect::<Result<_, _>>()
            .map_err(err)?,
        (hound::SampleFormat::Float, 32) => reader
            .samples::<f32>()
            .collect::<Result<_, _>>()
            .map_err(err)?,
        (format, bits) => {
            return Err(WavError::Format {
                path: path.to_path_buf(),
                bits,
                format,
            });
        }
    };
    let samples = interleaved
        .chunks(channels)
        .map(|frame| frame.iter().sum::<f32>() / frame.len() as f32)
        .collect();
    Ok(Clip {
        rate: spec.sample_rate,
        samples,
    })
}
