//! The built-in modules and the switch that picks them from the configuration.

use crate::config::Config;
use crate::module::Module;

pub mod behaviour;
pub mod brain;
pub mod tts;
pub mod vision;

/// The enabled built-in modules, in start order. The TTS module starts before
/// any other publisher of avatar commands: it owns `Agent.avatar` (the
/// behaviour controllers publish through it).
pub fn builtin(config: &Config) -> Vec<Box<dyn Module>> {
    let all: Vec<Box<dyn Module>> = vec![
        Box::new(tts::TtsModule),
        Box::new(brain::BrainModule),
        Box::new(vision::VisionModule),
    ];
    all.into_iter()
        .filter(|m| config.module_enabled(m.name()))
        .collect()
}
