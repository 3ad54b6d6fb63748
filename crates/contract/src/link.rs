//! The page link's JSON messages from the server (docs/browser-link.md): the `welcome` that opens each socket and
//! the once-a-second `status`. (Hub channels reach the page wrapped as `{"type": CHANNEL-KIND, "data": MESSAGE}`,
//! the message being the contract's type for that channel.)

use serde::{Deserialize, Serialize};

use crate::spectrum;

/// The microphone format the page must send.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AudioFormat {
    pub rate: u32,
    pub channels: u8,
    pub format: String,
    pub chunk_ms: u32,
}

/// The camera format the page must send.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VideoFormat {
    pub width: u32,
    pub height: u32,
    pub fps: u32,
    pub format: String,
}

/// What the spectrum frames hold.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FftFormat {
    pub size: usize,
    pub bins: usize,
    pub rate: u32,
    pub window: String,
    pub hop: usize,
    pub scale: String,
}

impl FftFormat {
    /// The spectra the audio_fft module makes ([`crate::spectrum`]), one every `hop` samples.
    pub fn of_spectra(hop: usize) -> Self {
        FftFormat {
            size: spectrum::FFT_SIZE,
            bins: spectrum::BINS,
            rate: spectrum::RATE,
            window: spectrum::WINDOW.into(),
            hop,
            scale: spectrum::SCALE.into(),
        }
    }
}

/// The microphone/camera role as the server sees it: `free`, `busy` (someone else holds it), `granted`,
/// `released`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoleInfo {
    pub state: String,
}

/// The first message on every page socket.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Welcome {
    /// Always `welcome`.
    #[serde(rename = "type")]
    pub kind: String,
    pub version: u32,
    /// This socket's page number.
    pub session: u64,
    pub server: String,
    pub audio: AudioFormat,
    pub video: VideoFormat,
    pub fft: FftFormat,
    pub role: RoleInfo,
    /// The language the agent converses in (`agent.language`, `en` or `it`): the page shows its controls in it
    /// unless `?lang=` chooses. Absent from servers that predate it, which speak English.
    #[serde(default = "english")]
    pub language: String,
    /// The engine that speaks that language by default (`piper`, the neural voice, or `espeak`, espeak-ng): the
    /// latency figure on the page names it. Absent from servers that predate it, which speak with espeak-ng.
    #[serde(default = "espeak")]
    pub voice: String,
}

fn english() -> String {
    "en".into()
}

fn espeak() -> String {
    "espeak".into()
}

/// Media counters of the last second.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Incoming {
    pub audio_fps: u64,
    pub video_fps: u64,
    /// The microphone's level over the second, or `null` in silence.
    pub audio_level_dbfs: Option<f64>,
}

/// Which media channels this page is publishing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Sending {
    pub audio: bool,
    pub video: bool,
}

/// Drop counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Dropped {
    /// Camera frames the server dropped because the hub lane was full.
    pub video_queue: u64,
    /// Media sent by a page that does not hold the role.
    pub not_holder: u64,
    /// Messages to this page dropped because it read too slowly.
    pub to_page: u64,
}

/// What the server advises the page to send.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Advice {
    pub video_fps: u32,
}

/// The once-a-second status.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// Always `status`.
    #[serde(rename = "type")]
    pub kind: String,
    /// `holder`, `waiting` or `none`.
    pub role: String,
    #[serde(rename = "in")]
    pub incoming: Incoming,
    pub sending: Sending,
    pub dropped: Dropped,
    pub audio_dropped: u64,
    pub advice: Advice,
}

/// The answer to the page's `{"type":"ping","t":...}`: its `t` back, and the server's clock, from which the page
/// estimates the offset between the two clocks (for latencies measured across them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pong {
    /// Always `pong`.
    #[serde(rename = "type")]
    pub kind: String,
    /// The page's `t`, unchanged.
    pub t: f64,
    /// The server's time when it answered (ms since the Unix epoch, with fractions).
    pub server_ms: f64,
}
