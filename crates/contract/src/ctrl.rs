//! `Agent.ctrl`: control messages from the page holding the role (or any satellite). A message carries one or more
//! of these fields and each consumer acts on its own: the TTS module on `say` and on a stop (`"speech": "stop"` or
//! `"cmd": "speech_stop"`), whisper satellites on `asr`, the recorder module on `record`. Other fields are for other consumers and are ignored.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ctrl {
    /// Speak this text (the page's "say" box).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub say: Option<String>,
    /// `stop`: stop all speech.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speech: Option<String>,
    /// `speech_stop`: stop all speech (the avatar command's name, accepted here too).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cmd: Option<String>,
    /// Listening on or off.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub asr: Option<bool>,
    /// Start (`true`) or stop (`false`) recording the session into an MCAP file (the recorder module).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record: Option<bool>,
}

impl Ctrl {
    /// Whether the message asks to stop speaking.
    pub fn stops_speech(&self) -> bool {
        self.speech.as_deref() == Some("stop") || self.cmd.as_deref() == Some("speech_stop")
    }
}
