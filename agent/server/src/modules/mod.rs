//! The built-in modules and the switch that picks them from the configuration.

use std::path::PathBuf;

use agent_brain::Language;

use flow_hub::module::Module;

mod acquaintances;
pub mod audio_fft;
pub mod brain;
pub mod echo;
mod luma;
pub mod observer;
mod on_demand;
pub mod recorder;
pub mod spectrum;
pub mod tts;
pub mod video_y;
pub mod vision;
pub mod vision_worker;

/// The built-in modules besides the browser link, in start order (the server starts those enabled), conversing
/// in `language`. The TTS module starts before any other publisher of avatar commands: it owns
/// `Agent.avatar` (the behaviour controllers publish through it).
pub fn builtin(language: Language, knowledge: Option<PathBuf>) -> Vec<Box<dyn Module>> {
    vec![
        Box::new(tts::TtsModule { language }),
        Box::new(brain::BrainModule {
            language,
            knowledge,
        }),
        Box::new(echo::EchoModule),
        Box::new(vision::VisionModule),
        Box::new(video_y::VideoY),
        Box::new(audio_fft::AudioFft),
        Box::new(observer::ObserverModule),
        Box::new(recorder::RecorderModule),
    ]
}
