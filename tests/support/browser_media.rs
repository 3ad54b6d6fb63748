//! Fixtures for the browser tests (converted from `../shared/fixtures` with ffmpeg at test setup) and the
//! measurements the tests make on what reaches the hub: audio energy envelopes, JPEG sizes and channels.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, bail};

use crate::browser_chromium::FakeMedia;
use crate::fixtures::fixtures;

/// The speech recording the microphone plays, at its original 22050 Hz (the reference for the envelope).
pub fn speech_fixture() -> PathBuf {
    fixtures().join("audio/derived/jfk_22050.wav")
}

/// Frequency of the test tone the FFT test plays.
pub const TONE_HZ: f64 = 1000.0;

/// Converts the fixtures into `dir`, keeping what is there (a shared folder is converted once per machine; delete
/// it after changing a conversion here): the speech and a test tone as 48 kHz WAV (what a
/// sound card gives, so the page's resampler has real work to do) and the camera frames as a 15 fps Y4M video.
pub fn prepare(dir: &Path) -> anyhow::Result<(FakeMedia, FakeMedia)> {
    std::fs::create_dir_all(dir)?;
    let fx = fixtures();
    let frames = fx.join("motion/derived/intel_one-by-one_t2-10s_640x360_15fps/frame_%04d.jpg");
    let video = dir.join("camera.y4m");
    let speech = dir.join("speech.wav");
    let tone = dir.join("tone.wav");
    if !video.exists() {
        convert(
            &video,
            &[
                "-framerate",
                "15",
                "-i",
                path_str(&frames)?,
                "-pix_fmt",
                "yuv420p",
            ],
        )?;
    }
    if !speech.exists() {
        convert(
            &speech,
            &[
                "-i",
                path_str(&speech_fixture())?,
                "-ar",
                "48000",
                "-ac",
                "1",
            ],
        )?;
    }
    if !tone.exists() {
        // A half-scale sine (ffmpeg's `sine` source has a fixed 1/8 amplitude, so the expression source is used).
        let src = format!("aevalsrc=0.5*sin(2*PI*{TONE_HZ}*t):s=48000:d=10");
        convert(
            &tone,
            &["-f", "lavfi", "-i", &src, "-ac", "1", "-c:a", "pcm_s16le"],
        )?;
    }
    Ok((
        FakeMedia {
            audio_wav: speech,
            video_y4m: video.clone(),
        },
        FakeMedia {
            audio_wav: tone,
            video_y4m: video,
        },
    ))
}

fn path_str(p: &Path) -> anyhow::Result<&str> {
    p.to_str()
        .with_context(|| format!("non-UTF-8 path {}", p.display()))
}

/// Runs ffmpeg with `args` into `out`, written under a name of this process's and renamed into place when whole:
/// the test processes of a run share the folder, and one must never read a file another is still writing.
fn convert(out: &Path, args: &[&str]) -> anyhow::Result<()> {
    let name = out
        .file_name()
        .and_then(|n| n.to_str())
        .with_context(|| format!("no file name in {}", out.display()))?;
    // ffmpeg picks the format by the extension, so the process's mark goes before it.
    let part = out.with_file_name(format!("{}.{name}", std::process::id()));
    let done = Command::new("ffmpeg")
        .args(["-loglevel", "error", "-y"])
        .args(args)
        .arg(&part)
        .output()
        .context("running ffmpeg (apt-get install ffmpeg)")?;
    if !done.status.success() {
        let _ = std::fs::remove_file(&part);
        bail!(
            "ffmpeg {args:?} failed: {}",
            String::from_utf8_lossy(&done.stderr)
        );
    }
    std::fs::rename(&part, out)
        .with_context(|| format!("moving {} to {}", part.display(), out.display()))
}

/// Reads a mono s16 WAV file's samples.
pub fn read_wav(path: &Path) -> anyhow::Result<(u32, Vec<i16>)> {
    let mut reader =
        hound::WavReader::open(path).with_context(|| format!("opening {}", path.display()))?;
    let spec = reader.spec();
    if spec.channels != 1 || spec.bits_per_sample != 16 {
        bail!("{}: expected mono 16-bit, got {spec:?}", path.display());
    }
    let samples = reader.samples::<i16>().collect::<Result<Vec<_>, _>>()?;
    Ok((spec.sample_rate, samples))
}

/// s16le bytes to samples.
pub fn pcm_samples(bytes: &[u8]) -> Vec<i16> {
    bytes
        .chunks_exact(2)
        .map(|b| i16::from_le_bytes([b[0], b[1]]))
        .collect()
}

/// RMS energy per window of `window` samples.
pub fn envelope(samples: &[i16], window: usize) -> Vec<f64> {
    samples
        .chunks_exact(window)
        .map(|w| {
            (w.iter().map(|&s| f64::from(s) * f64::from(s)).sum::<f64>() / window as f64).sqrt()
        })
        .collect()
}

/// The best Pearson correlation of `captured` against the looping `reference` over every circular lag: the fake
/// microphone plays its file in a loop from wherever it happens to be when the page starts listening.
pub fn best_loop_correlation(reference: &[f64], captured: &[f64]) -> f64 {
    let n = captured.len();
    if n < 2 || reference.is_empty() {
        return 0.0;
    }
    let (mc, sc) = mean_sd(captured);
    let mut best = f64::MIN;
    for lag in 0..reference.len() {
        let window: Vec<f64> = (0..n)
            .map(|i| reference[(lag + i) % reference.len()])
            .collect();
        let (mr, sr) = mean_sd(&window);
        if sr == 0.0 || sc == 0.0 {
            continue;
        }
        let cov = window
            .iter()
            .zip(captured)
            .map(|(r, c)| (r - mr) * (c - mc))
            .sum::<f64>()
            / n as f64;
        best = best.max(cov / (sr * sc));
    }
    best
}

fn mean_sd(v: &[f64]) -> (f64, f64) {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64;
    (m, var.sqrt())
}

/// A decoded JPEG's width, height and number of colour channels.
pub fn jpeg_shape(bytes: &[u8]) -> anyhow::Result<(u32, u32, u8)> {
    let img = image::load_from_memory_with_format(bytes, image::ImageFormat::Jpeg)?;
    Ok((img.width(), img.height(), img.color().channel_count()))
}

/// The frequency of the strongest bin of an `Agent.audio.fft` payload (f32le magnitudes, bin k = k*rate/size).
pub fn spectrum_peak(payload: &[u8], rate: f64, size: usize) -> (f64, f32) {
    let mags: Vec<f32> = payload
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let (k, m) =
        mags.iter().enumerate().skip(1).fold(
            (0, 0f32),
            |best, (k, &m)| if m > best.1 { (k, m) } else { best },
        );
    (k as f64 * rate / size as f64, m)
}

/// The questions the full-pipeline test's microphone asks, and when (seconds into its 20 s loop).
pub const PIPELINE_QUESTIONS: [(&str, f64); 2] =
    [("What time is it?", 8.0), ("Please read the code.", 16.0)];

/// Media for the full-pipeline test, converted once into `dir`: a camera that shows a portrait placed on the right
/// of the frame for 10 s, then a QR code for 10 s (looping), and a microphone that asks [`PIPELINE_QUESTIONS`] in
/// flite's voice (another engine than the agent's own espeak-ng), with silence around them.
pub fn prepare_pipeline(dir: &Path) -> anyhow::Result<FakeMedia> {
    std::fs::create_dir_all(dir)?;
    let fx = fixtures();
    let video = dir.join("pipeline.y4m");
    let audio = dir.join("pipeline.wav");
    if !video.exists() {
        let face = fx.join("faces/fr_obama.jpg");
        let code = fx.join("qr/derived/zxing_qrcode-1_17_640x360.jpg");
        // Each picture is a 10 s still at 15 fps.
        let mut args: Vec<&str> = Vec::new();
        for picture in [&face, &code] {
            args.extend(["-loop", "1", "-framerate", "15", "-t", "10", "-i"]);
            args.push(path_str(picture)?);
        }
        args.extend([
            "-filter_complex",
            "[0]scale=-2:330,pad=640:360:640-iw-20:15:black,setsar=1[a];[1]scale=640:360,setsar=1[b];[a][b]concat=n=2:v=1[v]",
            "-map",
            "[v]",
            "-pix_fmt",
            "yuv420p",
        ]);
        convert(&video, &args)?;
    }
    if !audio.exists() {
        let mut parts = Vec::new();
        for (i, (text, _)) in PIPELINE_QUESTIONS.iter().enumerate() {
            let wav = dir.join(format!("question-{i}.wav"));
            let out = Command::new("flite")
                .args(["-voice", "slt", "-t", text, "-o"])
                .arg(&wav)
                .output()
                .context("running flite (apt-get install flite)")?;
            if !out.status.success() {
                bail!("flite failed: {}", String::from_utf8_lossy(&out.stderr));
            }
            parts.push(wav);
        }
        // Each question is delayed to its start time and the sum padded to 20 s, at the 48 kHz of a sound card.
        let mut args: Vec<String> = Vec::new();
        for p in &parts {
            args.push("-i".into());
            args.push(path_str(p)?.to_owned());
        }
        let mut filter = String::new();
        for (i, (_, at)) in PIPELINE_QUESTIONS.iter().enumerate() {
            let ms = (at * 1000.0) as u64;
            filter.push_str(&format!("[{i}]aresample=48000,adelay={ms}[q{i}];"));
        }
        filter.push_str("[q0][q1]amix=inputs=2:normalize=0,apad=whole_dur=20,atrim=0:20[out]");
        args.extend(
            [
                "-filter_complex",
                &filter,
                "-map",
                "[out]",
                "-ac",
                "1",
                "-ar",
                "48000",
                "-c:a",
                "pcm_s16le",
            ]
            .map(str::to_owned),
        );
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        convert(&audio, &refs)?;
    }
    Ok(FakeMedia {
        audio_wav: audio,
        video_y4m: video,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loop_correlation_finds_a_shifted_copy_and_rejects_noise() {
        let reference: Vec<f64> = (0..200)
            .map(|i| ((i * 37 % 101) as f64).sin().abs())
            .collect();
        let shifted: Vec<f64> = (0..80)
            .map(|i| reference[(i + 150) % 200] * 3.0 + 1.0)
            .collect();
        assert!(best_loop_correlation(&reference, &shifted) > 0.99);
        let flat_ish: Vec<f64> = (0..80).map(|i| (i * 13 % 7) as f64).collect();
        assert!(best_loop_correlation(&reference, &flat_ish) < 0.6);
    }
}
