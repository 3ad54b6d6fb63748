//! The two payloads of the benchmark, cut from real fixtures: 20 ms of speech
//! as the `Agent.audio` channel carries it, and a 640x360 camera JPEG as on
//! `Agent.video`.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use crate::stamp::STAMP_LEN;

/// One payload and the rate its channel runs at in the product.
#[derive(Debug, Clone)]
pub struct Payload {
    pub name: &'static str,
    pub bytes: Vec<u8>,
    pub hz: f64,
    pub rate_label: &'static str,
}

/// `$AGENT_FIXTURES`, else `shared/fixtures` beside the repository.
pub fn default_fixtures() -> PathBuf {
    match std::env::var_os("AGENT_FIXTURES") {
        Some(dir) => PathBuf::from(dir),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/fixtures"),
    }
}

/// 441 samples (20 ms) of s16le mono 22050 Hz speech: 882 bytes.
pub fn audio(fixtures: &Path) -> anyhow::Result<Payload> {
    const RATE: u32 = 22050;
    const SAMPLES: usize = 441;
    let path = fixtures.join("audio/LJ001-0001.wav");
    let mut wav =
        hound::WavReader::open(&path).with_context(|| format!("opening {}", path.display()))?;
    let spec = wav.spec();
    if spec.sample_rate != RATE || spec.channels != 1 || spec.bits_per_sample != 16 {
        bail!(
            "{}: expected s16 mono {RATE} Hz, found {spec:?}",
            path.display()
        );
    }
    // One second in, where the speaker is talking.
    let samples: Vec<i16> = wav
        .samples::<i16>()
        .skip(RATE as usize)
        .take(SAMPLES)
        .collect::<Result<_, _>>()
        .with_context(|| format!("reading {}", path.display()))?;
    if samples.len() != SAMPLES {
        bail!("{}: shorter than 1 s + 20 ms", path.display());
    }
    let bytes = samples.iter().flat_map(|s| s.to_le_bytes()).collect();
    Ok(Payload {
        name: "audio",
        bytes,
        hz: 50.0,
        rate_label: "50 Hz",
    })
}

/// A real 640x360 camera-format JPEG.
pub fn jpeg(fixtures: &Path) -> anyhow::Result<Payload> {
    let path = fixtures.join("faces/derived/fr_two_people_640x360.jpg");
    let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    if bytes.len() < STAMP_LEN || !bytes.starts_with(&[0xff, 0xd8]) {
        bail!("{} is not a JPEG", path.display());
    }
    Ok(Payload {
        name: "jpeg",
        bytes,
        hz: 15.0,
        rate_label: "15 fps",
    })
}
