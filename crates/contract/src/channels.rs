//! The agent's channels: name, kind (1:N stream or 1:1 service) and, where the producer is fixed, its header.
//! A channel name appears nowhere else in the workspace (`tests/contract.rs` greps for stray literals).

/// A stream (1:N) or a service (1:1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Stream,
    Service,
}

/// One channel of the agent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channel {
    pub name: &'static str,
    pub kind: Kind,
    /// Who publishes it and what it carries.
    pub doc: &'static str,
}

const fn stream(name: &'static str, doc: &'static str) -> Channel {
    Channel {
        name,
        kind: Kind::Stream,
        doc,
    }
}

const fn service(name: &'static str, doc: &'static str) -> Channel {
    Channel {
        name,
        kind: Kind::Service,
        doc,
    }
}

/// The microphone: s16le mono PCM at 22050 Hz in 20 ms chunks, from the page holding the role (or any satellite).
pub const AUDIO: Channel = stream("Agent.audio", "microphone PCM (browser link)");
/// The microphone less the agent's own voice (the echo module, docs/voice.md): `Agent.audio`'s format, in whole
/// 10 ms frames; whisper satellites listen here when it exists. An empty message is a stream break: the
/// microphone's stream started again (a new publisher, a hole, a pause of 4 s), as a new sequence on
/// `Agent.audio` would say. Only while someone subscribes.
pub const AUDIO_CLEAN: Channel = stream(
    "Agent.audio.clean",
    "microphone PCM less the agent's echo (echo module)",
);
/// The camera: 640x360 JPEG frames at up to 15 fps.
pub const VIDEO: Channel = stream("Agent.video", "camera JPEG frames (browser link)");
/// The camera in grey (the Y plane as JPEG), only while someone subscribes.
pub const VIDEO_Y: Channel = stream("Agent.video.y", "grey camera frames (video_y module)");
/// Spectra of the microphone (f32le magnitudes), only while someone subscribes.
pub const AUDIO_FFT: Channel = stream("Agent.audio.fft", "microphone spectra (audio_fft module)");
/// Control messages from the page (`{"say": ...}`, `{"asr": bool}`...).
pub const CTRL: Channel = stream("Agent.ctrl", "page control messages (browser link)");
/// Avatar commands: blink, gaze, mood, visemes, speech_stop, say captions.
pub const AVATAR: Channel = stream("Agent.avatar", "avatar commands (tts module)");
/// Synthesised speech: `[utterance u32][offset u32][s16le PCM]`.
pub const SPEECH: Channel = stream("Agent.speech", "speech PCM (tts module)");
/// The `Agent.say` service: text in, utterance number out.
pub const SAY: Channel = service("Agent.say", "speak a text (tts module)");
/// Final transcripts and voice-activity events.
pub const TRANSCRIPT: Channel = stream("Agent.transcript", "transcripts (whisper-sat relay)");
/// The transcript of a pause, published as soon as it is decoded, before the end of the turn is decided
/// ([`crate::transcript::TranscriptMessage`] with `"final": false`): the brain may start the model's reply on it
/// (docs/llm.md, "Preemptive replies"). The final transcript on [`TRANSCRIPT`] follows, or not if the voice resumed.
pub const TRANSCRIPT_PAUSE: Channel = stream(
    "Agent.transcript.pause",
    "transcripts of pauses, before the end of the turn (whisper-sat relay)",
);
/// Faces of each processed frame ([`crate::detections::Faces`]).
pub const FACES: Channel = stream("Agent.faces", "face boxes (vision module)");
/// Motion of each processed frame ([`crate::detections::MotionReport`]).
pub const MOTION: Channel = stream("Agent.motion", "motion (vision module)");
/// New appearances of codes ([`crate::detections::Codes`]).
pub const CODES: Channel = stream("Agent.codes", "QR and barcodes (vision module)");
/// Everything seen in one frame ([`crate::detections::Detections`]): what the overlay draws, the gaze follows and
/// the brain perceives.
pub const DETECTIONS: Channel = stream(
    "Agent.detections",
    "all detections of a frame (vision module)",
);
/// Faces the agent was introduced to ([`crate::acquaintance`]): learn the talking person's face under a name, or
/// forget it (the brain's `learn_face` and `forget_face`).
pub const ACQUAINTANCES: Channel = service(
    "Agent.acquaintances",
    "learn or forget a face by name (vision module)",
);
/// The rule trace of the brain.
pub const RULES: Channel = stream("Agent.rules", "rule trace (brain module)");
/// Whether the session is being recorded, and where ([`crate::recording::RecordingState`]).
pub const RECORDING: Channel = stream("Agent.recording", "recording state (recorder module)");
/// One message per conversational turn with its stage latencies ([`crate::latency::TurnLatency`]).
pub const LATENCY: Channel = stream("Agent.latency", "turn latencies (observer module)");
/// When a page began playing each utterance of speech, on the server's clock ([`crate::say::PlaybackStarted`]): the
/// end of the turn as the user hears it (docs/telemetry.md).
pub const PLAYBACK: Channel = stream("Agent.playback", "speech playback starts (browser link)");
/// Where whisper satellites submit transcripts for the relay to publish once.
pub const ASR_SUBMIT: Channel = service(
    "Agent.asr.submit",
    "transcript submission (whisper-sat relay)",
);
/// Chat turns for a language-model satellite ([`crate::chat`]): a turn in, the reply out when it ends.
pub const CHAT: Channel = service("Agent.chat", "chat turns (llm-sat)");
/// The chat turns' prompts, sentences as they are generated, tool calls and ends ([`crate::chat::ChatEvent`]).
pub const CHAT_REPLY: Channel = stream("Agent.chat.reply", "chat reply sentences (llm-sat)");
/// The prefix of the per-utterance claim channels of whisper satellites (`Agent.asr.claim.<start>`).
pub const ASR_CLAIM_PREFIX: &str = "Agent.asr.claim.";
/// The prefix of the presence channels of whisper satellites (`Agent.asr.sat.<name>`).
pub const ASR_PRESENCE_PREFIX: &str = "Agent.asr.sat.";

/// Every channel with a fixed name.
pub const ALL: &[Channel] = &[
    AUDIO,
    AUDIO_CLEAN,
    VIDEO,
    VIDEO_Y,
    AUDIO_FFT,
    CTRL,
    AVATAR,
    SPEECH,
    SAY,
    TRANSCRIPT,
    TRANSCRIPT_PAUSE,
    FACES,
    MOTION,
    CODES,
    DETECTIONS,
    ACQUAINTANCES,
    RULES,
    LATENCY,
    RECORDING,
    ASR_SUBMIT,
    CHAT,
    CHAT_REPLY,
    PLAYBACK,
];

/// Headers of the channels whose producer is fixed.
pub mod headers {
    /// `Agent.audio` from the page.
    pub const AUDIO: &str =
        r#"{"format":"s16le","rate":22050,"channels":1,"chunk_ms":20,"source":"browser"}"#;
    /// `Agent.audio.clean` from the echo module: whole 10 ms frames (220 samples, WebRTC's frame at this rate).
    pub const AUDIO_CLEAN: &str = r#"{"format":"s16le","rate":22050,"channels":1,"frame_samples":220,"source":"Agent.audio","echo":"cancelled against Agent.speech","break":"empty message"}"#;
    /// `Agent.video` from the page.
    pub const VIDEO: &str =
        r#"{"format":"jpeg","width":640,"height":360,"fps":15,"source":"browser"}"#;
    /// `Agent.ctrl` from the page.
    pub const CTRL: &str = r#"{"format":"json","source":"browser"}"#;
    /// `Agent.playback` from the page link.
    pub const PLAYBACK: &str =
        r#"{"format":"json","content":"speech playback starts","source":"browser"}"#;
    /// `Agent.video.y`.
    pub const VIDEO_Y: &str =
        r#"{"format":"jpeg","colour":"grey","width":640,"height":360,"source":"Agent.video"}"#;
    /// `Agent.avatar`.
    pub const AVATAR: &str = r#"{"format":"json","commands":["blink","gaze","mood","visemes","speech_stop","say"],"source":"tts"}"#;
    /// `Agent.say`: what it takes and answers.
    pub const SAY: &str = r#"{"request":{"text":"string","voice":"optional espeak-ng voice","rate_wpm":"optional","pitch":"optional"},"cancel":{"cancel":"all | utterance number"},"mood":{"mood":"happy | surprised | sad | angry | thinking | listening | neutral"},"answer":{"utterance":"number","cancelled":"[numbers]"}}"#;
    /// `Agent.chat`: what it takes and answers.
    pub const CHAT: &str = r#"{"request":"agent_contract::chat::ChatRequest","cancel":{"cancel":"turn"},"answer":"agent_contract::chat::ChatAnswer","doc":"docs/llm.md"}"#;
    /// `Agent.chat.reply`.
    pub const CHAT_REPLY: &str =
        r#"{"format":"json","content":"chat events","source":"llm-sat","doc":"docs/llm.md"}"#;
    /// `Agent.rules`.
    pub const RULES: &str = r#"{"format":"json","content":"rule trace","doc":"docs/brain.md"}"#;
    /// `Agent.transcript`.
    pub const TRANSCRIPT: &str = r#"{"mime":"application/json"}"#;
    /// `Agent.recording`.
    pub const RECORDING: &str = r#"{"format":"json","content":"recording state","source":"recorder","doc":"docs/recording.md"}"#;
    /// `Agent.latency`.
    pub const LATENCY: &str = r#"{"format":"json","content":"turn latencies","source":"observer","doc":"docs/metrics.md"}"#;

    /// `Agent.acquaintances`: what it takes and answers.
    pub const ACQUAINTANCES: &str = r#"{"request":"agent_contract::acquaintance::AcquaintanceRequest","answer":"agent_contract::acquaintance::AcquaintanceAnswer","doc":"docs/vision.md"}"#;

    /// The header of one of the vision module's JSON channels (`content`: faces, motion, codes or detections).
    pub fn vision(content: &str) -> String {
        serde_json::json!({"format": "json", "source": "vision", "content": content, "doc": "docs/vision.md"})
            .to_string()
    }

    /// `Agent.audio.fft`: spectra every `hop` samples ([`crate::spectrum`]).
    pub fn audio_fft(hop: usize) -> String {
        use crate::spectrum::{BINS, FFT_SIZE, FORMAT, RATE, SCALE, WINDOW};
        serde_json::json!({
            "format": FORMAT, "size": FFT_SIZE, "bins": BINS, "rate": RATE, "window": WINDOW, "hop": hop,
            "scale": SCALE,
        })
        .to_string()
    }

    /// `Agent.speech`: PCM framed per utterance (docs/browser-link.md).
    pub fn speech(rate: u32, chunk_ms: u32) -> String {
        serde_json::json!({
            "format": "s16le", "rate": rate, "channels": 1, "chunk_ms": chunk_ms,
            "framing": "utterance-offset", "source": "tts",
        })
        .to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_valid_hub_names() {
        let mut names: Vec<&str> = ALL.iter().map(|c| c.name).collect();
        names.sort_unstable();
        let before = names.len();
        names.dedup();
        assert_eq!(before, names.len(), "a name is listed twice");
        for c in ALL {
            assert!(c.name.starts_with("Agent."), "{}", c.name);
            assert!(
                c.name
                    .chars()
                    .all(|ch| ch.is_ascii_alphanumeric() || ch == '.' || ch == '_')
            );
        }
    }

    #[test]
    fn fixed_headers_are_json_objects() {
        for h in [
            headers::AUDIO,
            headers::AUDIO_CLEAN,
            headers::VIDEO,
            headers::CTRL,
            headers::PLAYBACK,
            headers::VIDEO_Y,
            headers::AVATAR,
            headers::SAY,
            headers::RULES,
            headers::TRANSCRIPT,
            headers::LATENCY,
            headers::RECORDING,
            &headers::vision("faces"),
            &headers::speech(22050, 20),
            &headers::audio_fft(1024),
        ] {
            let v: serde_json::Value = serde_json::from_str(h).expect(h);
            assert!(v.is_object(), "{h}");
        }
        assert!(headers::VIDEO_Y.contains(VIDEO.name));
    }
}
