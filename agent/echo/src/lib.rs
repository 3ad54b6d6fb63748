//! Echo cancellation: the microphone less the agent's own voice, once per microphone, before voice activity.
//!
//! The loudspeaker plays the agent's speech (`Agent.speech`) and the microphone hears it back through the room.
//! [`Canceller`] removes that echo from the microphone stream with WebRTC's AEC3 (the `sonora` port): an adaptive
//! filter that estimates the loudspeaker-to-microphone delay and the room's response itself, and a suppressor for
//! what the filter leaves, which keeps a user talking over the agent (double talk). The far-end reference is the
//! speech placed on the hub clock where the page plays it ([`reference::Reference`]); what the filter leaves is silenced by a gate
//! with a learned floor ([`residual::ResidualGate`]); the microphone's samples are placed on the same clock from the hub's stamps ([`clock::MicClock`]). Everything here is pure computation over
//! samples and stamps: the robot-agent's `echo` module feeds it from the hub (docs/voice.md, "Echo cancellation").

pub mod canceller;
pub mod clock;
pub mod hold;
pub mod onset;
pub mod presence;
pub mod rate;
pub mod reference;
pub mod residual;

pub use canceller::{Canceller, CancellerConfig, CancellerError, CancellerStats};
pub use rate::{RATE, samples_us};
