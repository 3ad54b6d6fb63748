//! Spoken test sentences: text said by the real espeak-ng command (the same synthesiser the agent speaks with),
//! trimmed to its voice and put together with exact silences, written as the 22050 Hz mono WAV `flowctl pub-wav`
//! streams. For timing tests that need a pause of a known length inside a sentence.

use std::path::Path;

use anyhow::{Context, bail};

/// The rate of `Agent.audio`, and espeak-ng's own.
pub const RATE: u32 = 22_050;

/// Samples quieter than this (s16) at the edges of a synthesised phrase are its padding, not its voice.
const EDGE_LEVEL: i16 = 300;

/// `text` said by espeak-ng at its default voice and rate, without the silence it pads the phrase with.
pub fn say(text: &str, dir: &Path) -> anyhow::Result<Vec<i16>> {
    let path = dir.join("espeak-phrase.wav");
    let status = std::process::Command::new("espeak-ng")
        .arg("-w")
        .arg(&path)
        .arg(text)
        .status()
        .context("running espeak-ng (apt install espeak-ng; make test installs it)")?;
    if !status.success() {
        bail!("espeak-ng failed on {text:?}: {status}");
    }
    let mut reader = hound::WavReader::open(&path).context("reading espeak-ng's WAV")?;
    let spec = reader.spec();
    if spec.sample_rate != RATE || spec.channels != 1 || spec.bits_per_sample != 16 {
        bail!("espeak-ng wrote {spec:?}, expected {RATE} Hz mono s16");
    }
    let samples: Vec<i16> = reader.samples::<i16>().collect::<Result<_, _>>()?;
    Ok(trim(&samples).to_vec())
}

/// The part of `samples` from the first to the last sample louder than the edge level.
pub fn trim(samples: &[i16]) -> &[i16] {
    let loud = |s: &i16| s.unsigned_abs() > EDGE_LEVEL.unsigned_abs();
    let first = samples.iter().position(loud).unwrap_or(0);
    let last = samples.iter().rposition(loud).map_or(first, |i| i + 1);
    &samples[first..last]
}

/// `ms` of digital silence.
pub fn silence(ms: u32) -> Vec<i16> {
    vec![0; (RATE * ms / 1000) as usize]
}

/// Writes `samples` as a 22050 Hz mono s16 WAV.
pub fn write_wav(path: &Path, samples: &[i16]) -> anyhow::Result<()> {
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: RATE,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    };
    let mut writer = hound::WavWriter::create(path, spec)
        .with_context(|| format!("creating {}", path.display()))?;
    for s in samples {
        writer.write_sample(*s)?;
    }
    writer.finalize()?;
    Ok(())
}

/// Reads a 22050 Hz mono s16 WAV (a fixture, or what sox wrote).
pub fn read_wav(path: &Path) -> anyhow::Result<Vec<i16>> {
    let mut reader =
        hound::WavReader::open(path).with_context(|| format!("opening {}", path.display()))?;
    let spec = reader.spec();
    if spec.sample_rate != RATE || spec.channels != 1 || spec.bits_per_sample != 16 {
        bail!("{}: {spec:?}, expected {RATE} Hz mono s16", path.display());
    }
    Ok(reader.samples::<i16>().collect::<Result<_, _>>()?)
}

/// What a microphone across the room hears of `speech` played through a loudspeaker: delayed by `delay_ms`,
/// with room reverb, `attenuation_db` quieter; made by the real sox (`reverb`, `pad`, `gain`).
pub fn room_echo(
    speech: &[i16],
    delay_ms: u32,
    attenuation_db: f32,
    dir: &Path,
) -> anyhow::Result<Vec<i16>> {
    let dry = dir.join("echo-dry.wav");
    let wet = dir.join("echo-wet.wav");
    write_wav(&dry, speech)?;
    let status = std::process::Command::new("sox")
        .arg("-G")
        .arg(&dry)
        .args(["-b", "16"])
        .arg(&wet)
        .args(["reverb", "50", "50", "80"])
        .args(["pad", &format!("{:.3}", f64::from(delay_ms) / 1000.0)])
        .args(["gain", &format!("-{attenuation_db}")])
        .status()
        .context("running sox (apt install sox; make test installs it)")?;
    if !status.success() {
        bail!("sox failed: {status}");
    }
    read_wav(&wet)
}

/// `a` and `b` added sample by sample (clipped), `b` starting `offset` samples into `a`; as long as the longer.
pub fn mix(a: &[i16], b: &[i16], offset: usize) -> Vec<i16> {
    let len = a.len().max(offset + b.len());
    (0..len)
        .map(|i| {
            let x = i32::from(a.get(i).copied().unwrap_or(0));
            let y = i
                .checked_sub(offset)
                .and_then(|j| b.get(j))
                .map_or(0, |&s| i32::from(s));
            (x + y).clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16
        })
        .collect()
}

/// `text` in lower case with its punctuation gone and single spaces, for comparing what was heard with what was said.
pub fn words(text: &str) -> String {
    text.to_lowercase()
        .chars()
        .map(|c| if c.is_alphanumeric() { c } else { ' ' })
        .collect::<String>()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}
