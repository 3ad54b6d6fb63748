//! The robot agent: the flow hub (crate `flow-hub`) with the agent's in-server modules (vision, TTS and behaviour,
//! the rule brain, the grey-video and spectrum modules) and the browser link that serves the avatar page. See
//! ARCHITECTURE.md for the map.

pub mod browser;
pub mod modules;

use agent_brain::Language;
use flow_hub::module::Module;
use flow_hub::{Application, Config, RunningServer};
use tokio::sync::watch;

/// Starts the hub with every agent module and the page link, as `make run` does.
pub async fn start(config: Config) -> anyhow::Result<RunningServer> {
    let app = application(&config)?;
    flow_hub::start(config, app).await
}

/// The agent as an application of the hub: its modules and the page link.
pub fn application(config: &Config) -> anyhow::Result<Application> {
    let language: Language = config
        .agent
        .language
        .parse()
        .map_err(|e: agent_brain::UnknownLanguage| config.error("agent.language", e.to_string()))?;
    let shutdown = watch::channel(false).0;
    // The page is told the spectra's hop, which the audio_fft module's section sets.
    let fft_hop = modules::audio_fft::AudioFftParams::from_json(&config.module("audio_fft"))
        .map_err(|e| config.module_error("browser", &format!("{e:#}")))?
        .hop;
    // And which engine speaks: the latency figure names it.
    let voice = match modules::tts::params::TtsParams::from_json(&config.module("tts"))
        .map_err(|e| config.module_error("tts", &format!("{e:#}")))?
        .voice_settings(language)
        .engine
    {
        agent_voice::Engine::Piper => "piper",
        agent_voice::Engine::Espeak => "espeak",
    };
    let browser = browser::BrowserLink::from_config(config, fft_hop, voice, shutdown.subscribe())
        .map_err(|e| config.module_error("browser", &format!("{e:#}")))?;
    let knowledge = Some(config.agent.knowledge.trim())
        .filter(|dir| !dir.is_empty())
        .map(std::path::PathBuf::from);
    let modules: Vec<Box<dyn Module>> = modules::builtin(language, knowledge)
        .into_iter()
        .chain(std::iter::once(browser.module()))
        .collect();
    Ok(Application {
        modules,
        routes: browser.router(),
        shutdown,
    })
}
