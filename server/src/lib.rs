//! The robot agent: the flow hub (crate `flow-hub`) with the agent's in-server modules (vision, TTS and behaviour,
//! the rule brain, the grey-video and spectrum modules) and the browser link that serves the avatar page. See
//! ARCHITECTURE.md for the map.

pub mod browser;
pub mod modules;

// The hub's parts the modules build on, under the paths they have always used.
pub use flow_hub::{Config, RunningServer, Shared, config, http, module};

use agent_brain::Language;
use flow_hub::Application;
use flow_hub::module::Module;
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
    let browser = browser::BrowserLink::from_config(config, shutdown.subscribe())
        .map_err(|e| config.module_error("browser", &format!("{e:#}")))?;
    let modules: Vec<Box<dyn Module>> = modules::builtin(language)
        .into_iter()
        .chain(std::iter::once(browser.module()))
        .collect();
    Ok(Application {
        modules,
        routes: browser.router(),
        shutdown,
    })
}
