//! The built-in modules and the switch that picks them from the configuration.

use crate::module::Module;

pub mod behaviour;
pub mod brain;
pub mod tts;
pub mod vision;

/// The built-in modules, in start order (the server starts those enabled). The
/// TTS module starts before any other publisher of avatar commands: it owns
/// `Agent.avatar` (the behaviour controllers publish through it).
pub fn builtin() -> Vec<Box<dyn Module>> {
    vec![
        Box::new(tts::TtsModule),
        Box::new(brain::BrainModule),
        Box::new(vision::VisionModule),
    ]
}
