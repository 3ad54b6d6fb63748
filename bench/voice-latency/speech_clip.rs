//! The user's side: real recorded utterances, where their speech ends, and a microphone stand-in that publishes
//! `Agent.audio` in real time (20 ms s16le chunks at 22050 Hz, silence between utterances).

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use bytes::Bytes;
use flow::Publisher;
use tokio::sync::{mpsc, oneshot};

pub const RATE: u32 = 22_050;
/// Samples per 20 ms chunk, what a browser microphone sends.
const CHUNK: usize = 441;
const CHUNK_TIME: Duration = Duration::from_millis(20);
/// The end of speech is the end of the last 10 ms window whose level is within this many dB of the clip's loudest
/// window: quiet enough to keep soft word endings, loud enough to ignore the recording's room noise.
const VOICED_BELOW_PEAK_DB: f64 = 35.0;
const WINDOW: usize = RATE as usize / 100;

/// How an utterance ends, as a listener would judge it: the benchmark's targets are for whole turns, and phrases
/// cut inside a sentence show what holding an unfinished sentence open costs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// A whole sentence, question or command: the end of a turn.
    Turn,
    /// The first phrase of a longer sentence, cut at the pause after it: the speaker is not done.
    MidSentence,
}

impl Ending {
    pub fn label(self) -> &'static str {
        match self {
            Ending::Turn => "turn",
            Ending::MidSentence => "mid-sentence",
        }
    }
}

/// One utterance to say.
#[derive(Debug, Clone)]
pub struct Clip {
    pub name: String,
    pub samples: Vec<i16>,
    /// Index just past the last voiced sample.
    pub voiced_end: usize,
    /// Index of the first voiced sample (the start of its 10 ms window).
    pub voiced_start: usize,
    pub ending: Ending,
}

impl Clip {
    /// `text` said by espeak-ng (the synthesiser the agent itself speaks with), trimmed to its voice: the fixtures
    /// hold read sentences, and a conversation is mostly questions and commands.
    pub fn espeak(text: &str, dir: &Path) -> anyhow::Result<Clip> {
        let path = dir.join("voice-latency-espeak.wav");
        let status = std::process::Command::new("espeak-ng")
            .arg("-w")
            .arg(&path)
            .arg(text)
            .status()
            .context("running espeak-ng (apt install espeak-ng)")?;
        if !status.success() {
            bail!("espeak-ng failed on {text:?}: {status}");
        }
        let mut clip = Clip::load(&path, None, None, Ending::Turn)?;
        // espeak pads the phrase with silence; the voice itself is what is said.
        clip.samples.truncate(clip.voiced_end);
        clip.name = text.to_owned();
        Ok(clip)
    }

    /// The first `ms` of `clip`'s voice: a burst too short to be speech (a cough, a "hm").
    pub fn burst(clip: &Clip, ms: u32) -> Clip {
        let from = clip.voiced_start;
        let to = (from + (RATE * ms / 1000) as usize).min(clip.samples.len());
        let samples = clip.samples[from..to].to_vec();
        Clip {
            name: format!("{ms} ms of {:?}", clip.name),
            voiced_end: samples.len(),
            voiced_start: 0,
            samples,
            ending: clip.ending,
        }
    }

    /// Loads a 22050 Hz mono s16le WAV fixture, from `start_s` and cut after `cut_s` seconds (of the file) if
    /// given, and locates its end of speech.
    pub fn load(
        path: &Path,
        start_s: Option<f64>,
        cut_s: Option<f64>,
        ending: Ending,
    ) -> anyhow::Result<Clip> {
        let mut reader =
            hound::WavReader::open(path).with_context(|| format!("opening {}", path.display()))?;
        let spec = reader.spec();
        if spec.sample_rate != RATE || spec.channels != 1 || spec.bits_per_sample != 16 {
            bail!(
                "{}: expected 22050 Hz mono 16-bit, got {} Hz, {} channel(s), {} bits",
                path.display(),
                spec.sample_rate,
                spec.channels,
                spec.bits_per_sample
            );
        }
        let mut samples: Vec<i16> = reader
            .samples::<i16>()
            .collect::<Result<_, _>>()
            .with_context(|| format!("reading {}", path.display()))?;
        if let Some(cut) = cut_s {
            samples.truncate((cut * f64::from(RATE)) as usize);
        }
        if let Some(start) = start_s {
            samples.drain(..((start * f64::from(RATE)) as usize).min(samples.len()));
        }
        let voiced_end =
            voiced_end(&samples).with_context(|| format!("{}: no speech", path.display()))?;
        let voiced_start = voiced_start(&samples).unwrap_or(0);
        let name = path
            .file_stem()
            .map_or_else(|| "clip".into(), |s| s.to_string_lossy().into_owned());
        Ok(Clip {
            name,
            samples,
            voiced_end,
            voiced_start,
            ending,
        })
    }

    pub fn seconds(&self) -> f64 {
        self.samples.len() as f64 / f64::from(RATE)
    }
}

/// Index of the first voiced 10 ms window (see [`VOICED_BELOW_PEAK_DB`]).
fn voiced_start(samples: &[i16]) -> Option<usize> {
    let power = window_power(samples);
    let floor = voiced_floor(&power)?;
    Some(power.iter().position(|&p| p >= floor)? * WINDOW)
}

fn window_power(samples: &[i16]) -> Vec<f64> {
    samples
        .chunks(WINDOW)
        .map(|w| w.iter().map(|&s| f64::from(s).powi(2)).sum::<f64>() / w.len() as f64)
        .collect()
}

/// The level a window must reach to count as voiced; `None` for silence.
fn voiced_floor(power: &[f64]) -> Option<f64> {
    let peak = power.iter().copied().fold(0.0, f64::max);
    (peak > 0.0).then(|| peak * 10f64.powf(-VOICED_BELOW_PEAK_DB / 10.0))
}

/// Index just past the last voiced 10 ms window (see [`VOICED_BELOW_PEAK_DB`]).
fn voiced_end(samples: &[i16]) -> Option<usize> {
    let power = window_power(samples);
    let floor = voiced_floor(&power)?;
    let last = power.iter().rposition(|&p| p >= floor)?;
    Some(((last + 1) * WINDOW).min(samples.len()))
}

/// A request to say a clip; answered with the wall time at which the chunk holding its last voiced sample was
/// published (the earliest moment the server could know the speech was over).
pub struct Say {
    pub clip: Clip,
    pub spoken: oneshot::Sender<Instant>,
    /// Told the wall time at which the chunk holding the first voiced sample was published (the onset).
    pub onset: Option<oneshot::Sender<Instant>>,
}

/// Says `clip` through the microphone task; returns when the chunk holding its last voiced sample went out.
pub async fn say(tx: &mpsc::Sender<Say>, clip: &Clip) -> anyhow::Result<Instant> {
    let (spoken, spoken_rx) = oneshot::channel();
    tx.send(Say {
        clip: clip.clone(),
        spoken,
        onset: None,
    })
    .await
    .context("the microphone stopped")?;
    spoken_rx.await.context("the microphone stopped")
}

/// Publishes 20 ms chunks on a fixed real-time schedule: silence, or the clips it is asked to say. A chunk is
/// published when its last sample has been "captured", as a microphone would, so chunk `k` leaves at
/// `start + (k + 1) x 20 ms`. Runs until the request queue closes.
pub async fn microphone(
    publisher: Publisher,
    mut requests: mpsc::Receiver<Say>,
) -> anyhow::Result<()> {
    let start = tokio::time::Instant::now();
    let mut chunk_no: u32 = 0;
    let silence = vec![0i16; CHUNK];
    // The clip being said, the position in it, and who waits for its end of speech.
    let mut current: Option<(Clip, usize, Option<oneshot::Sender<Instant>>)> = None;
    let mut onset: Option<(usize, oneshot::Sender<Instant>)> = None;
    loop {
        if current.is_none() {
            match requests.try_recv() {
                Ok(say) => {
                    onset = say.onset.map(|tx| (say.clip.voiced_start, tx));
                    current = Some((say.clip, 0, Some(say.spoken)));
                }
                Err(mpsc::error::TryRecvError::Empty) => {}
                Err(mpsc::error::TryRecvError::Disconnected) => return Ok(()),
            }
        }
        let mut ends_speech = None;
        let mut starts_speech = None;
        let samples = match &mut current {
            Some((clip, pos, spoken)) => {
                let end = (*pos + CHUNK).min(clip.samples.len());
                if onset
                    .as_ref()
                    .is_some_and(|(at, _)| (*pos..end).contains(at))
                {
                    starts_speech = onset.take().map(|(_, tx)| tx);
                }
                let mut chunk = clip.samples[*pos..end].to_vec();
                chunk.resize(CHUNK, 0);
                if (*pos..end).contains(&(clip.voiced_end - 1)) {
                    ends_speech = spoken.take();
                }
                *pos = end;
                let finished = end == clip.samples.len();
                if finished {
                    current = None;
                }
                chunk
            }
            None => silence.clone(),
        };
        chunk_no += 1;
        tokio::time::sleep_until(start + CHUNK_TIME * chunk_no).await;
        let pcm: Vec<u8> = samples.iter().flat_map(|s| s.to_le_bytes()).collect();
        publisher.publish(Bytes::from(pcm)).await?;
        if let Some(onset) = starts_speech {
            let _ = onset.send(Instant::now());
        }
        if let Some(spoken) = ends_speech {
            // The waiter may have given up; the stream goes on regardless.
            let _ = spoken.send(Instant::now());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn end_of_speech_is_the_last_loud_window() {
        let mut s = vec![0i16; RATE as usize];
        for (i, v) in s.iter_mut().enumerate().take(11_025).skip(2205) {
            *v = if i % 2 == 0 { 8000 } else { -8000 };
        }
        // A faint tail far below the peak is not speech.
        for v in s.iter_mut().skip(15_000).take(100) {
            *v = 20;
        }
        // The end of the 10 ms window holding the last loud sample.
        let end = voiced_end(&s).expect("speech");
        assert!((11_025..11_025 + WINDOW).contains(&end), "{end}");
        assert_eq!(voiced_end(&[0; 1000]), None);
    }
}
