//! The speech the ASR benchmarks run on: clips read and resampled to Whisper's rate, their utterances as the
//! satellite's segmenter cuts them (with the audio times the latency figures need), small statistics and peak memory.

use std::path::{Path, PathBuf};
use std::time::Duration;

use whisper_sat::model_path::{FIXTURE_CLIPS, fixtures_dir};
use whisper_sat::resample::resample_clip;
use whisper_sat::segmenter::{RATE, SegmentEvent, Segmenter, SegmenterConfig};

// The benches' shared quantile (nearest index, NaN for no samples), as the satellite figures have always used.
pub(super) use agent_bench::percentile;

pub(super) struct ClipAudio {
    pub(super) name: String,
    pub(super) path: PathBuf,
    pub(super) audio: Vec<f32>,
}

impl ClipAudio {
    pub(super) fn seconds(&self) -> f64 {
        self.audio.len() as f64 / f64::from(RATE)
    }
}

pub(super) fn median(v: &[f64]) -> f64 {
    percentile(v, 0.5)
}

/// Peak resident memory of this process in MB.
pub(super) fn peak_rss_mb() -> f64 {
    process_peak_rss_mb("self")
}

/// Peak resident memory of process `pid` ("self" for this one) in MB, from Linux's `VmHWM`; NaN if unknown.
pub(super) fn process_peak_rss_mb(pid: &str) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// The fixture clips.
pub(super) fn load_clips() -> anyhow::Result<Vec<ClipAudio>> {
    FIXTURE_CLIPS
        .iter()
        .map(|name| clip_from(name, &fixtures_dir().join(format!("audio/{name}.wav"))))
        .collect()
}

/// A WAV file read and resampled to Whisper's rate.
pub(super) fn clip_from(name: &str, path: &Path) -> anyhow::Result<ClipAudio> {
    let clip = whisper_sat::wav::read_mono(path)?;
    Ok(ClipAudio {
        name: name.to_owned(),
        audio: resample_clip(&clip.samples, clip.rate, RATE)?,
        path: path.to_path_buf(),
    })
}

/// One utterance of a clip as the satellite's segmenter reports it, with audio times from its end of speech.
pub(super) struct Segmented {
    pub(super) audio: Vec<f32>,
    /// Until the segmenter ends it (the hangover).
    end_lag: Duration,
    /// Until it paused with exactly the audio it ended with, if it did: a speculative decode starts there.
    pause_lag: Option<Duration>,
}

impl Segmented {
    /// End of speech to transcript for a decode taking `inference`: with speculation, and without.
    pub(super) fn latency(&self, inference: Duration) -> (Duration, Duration) {
        let plain = self.end_lag + inference;
        let speculative = self
            .pause_lag
            .map_or(plain, |pause| self.end_lag.max(pause + inference));
        (speculative, plain)
    }
}

/// The utterances of a clip.
pub(super) fn segment(audio: &[f32]) -> anyhow::Result<Vec<Segmented>> {
    let mut seg = Segmenter::new(SegmenterConfig::default())?;
    let mut out = Vec::new();
    let mut events = Vec::new();
    let mut pause = None;
    let lag = |at: u64, speech_end: u64| {
        Duration::from_secs_f64((at - speech_end) as f64 / f64::from(RATE))
    };
    // Feed in 20 ms messages with a second of silence after the clip, as the hub would deliver them.
    let padded = [audio, &vec![0.0; RATE as usize]].concat();
    for chunk in padded.chunks(320) {
        seg.push(chunk, &mut events);
        for ev in events.drain(..) {
            match ev {
                SegmentEvent::Paused(u) => pause = Some((u, seg.position())),
                SegmentEvent::Resumed { .. } => pause = None,
                SegmentEvent::Ended(u) => {
                    let pause_lag = pause
                        .take()
                        .filter(|(p, _)| *p == u)
                        .map(|(p, at)| lag(at, p.speech_end));
                    out.push(Segmented {
                        end_lag: lag(seg.position(), u.speech_end),
                        pause_lag,
                        audio: u.audio,
                    });
                }
                _ => {}
            }
        }
    }
    Ok(out)
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speculation_hides_the_inference_behind_the_rest_of_the_hangover() {
        let ms = Duration::from_millis;
        let paused = Segmented {
            audio: Vec::new(),
            end_lag: ms(300),
            pause_lag: Some(ms(160)),
        };
        // A short decode is done before the end: the transcript goes out when the utterance ends.
        assert_eq!(paused.latency(ms(100)), (ms(300), ms(400)));
        // A longer one finishes after the end, still 140 ms sooner than one started there.
        assert_eq!(paused.latency(ms(250)), (ms(410), ms(550)));
        // Without a pause of the same audio (a cut at the maximum length) nothing is gained.
        let cut = Segmented {
            pause_lag: None,
            ..paused
        };
        assert_eq!(cut.latency(ms(250)), (ms(550), ms(550)));
    }
}
