//! Server configuration: defaults embedded from `config/default.toml`, a user
//! file layered on top, command-line overrides last. Every error names the
//! file, the key and the reason.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use thiserror::Error;

/// The embedded default configuration.
pub const DEFAULT_TOML: &str = include_str!("../../config/default.toml");

#[derive(Debug, Error)]
#[error("{file}: {key}: {reason}")]
pub struct ConfigError {
    pub file: String,
    pub key: String,
    pub reason: String,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Config {
    pub server: ServerSection,
    pub hub: HubSection,
    pub ticks: TickSection,
    /// `[modules.NAME]` tables, handed to each module as JSON parameters.
    #[serde(default)]
    pub modules: BTreeMap<String, toml::Table>,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ServerSection {
    pub http: String,
    pub flow_tcp: String,
    pub flow_unix: String,
    pub data_dir: PathBuf,
    pub log: String,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct HubSection {
    pub max_frame: usize,
    pub subscriber_queue: usize,
    pub subscriber_queue_bytes: usize,
    pub control_queue: usize,
    pub service_inflight: usize,
    pub io_threads: usize,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TickSection {
    pub fast_ms: u64,
    pub slow_ms: u64,
}

impl Config {
    /// The embedded defaults, optionally overlaid with the file at `path`.
    pub fn load(path: Option<&Path>) -> Result<Config, ConfigError> {
        let mut merged: toml::Table = parse_table("<embedded default.toml>", DEFAULT_TOML)?;
        let file = match path {
            Some(p) => {
                let name = p.display().to_string();
                let text = std::fs::read_to_string(p).map_err(|e| ConfigError {
                    file: name.clone(),
                    key: "-".into(),
                    reason: format!("cannot read: {e}"),
                })?;
                overlay(&mut merged, parse_table(&name, &text)?);
                name
            }
            None => "<embedded default.toml>".to_string(),
        };
        let config: Config =
            serde_path_to_error::deserialize(toml::Value::Table(merged)).map_err(|e| {
                ConfigError {
                    file: file.clone(),
                    key: e.path().to_string(),
                    reason: e.inner().to_string(),
                }
            })?;
        config.validate().map_err(|(key, reason)| ConfigError {
            file,
            key: key.into(),
            reason,
        })?;
        Ok(config)
    }

    fn validate(&self) -> Result<(), (&'static str, String)> {
        let addr = |key, v: &str, may_be_empty| {
            if may_be_empty && v.is_empty() {
                return Ok(());
            }
            v.parse::<SocketAddr>()
                .map(drop)
                .map_err(|e| (key, format!("{v:?} is not HOST:PORT ({e})")))
        };
        addr("server.http", &self.server.http, false)?;
        addr("server.flow_tcp", &self.server.flow_tcp, true)?;
        let h = &self.hub;
        if h.max_frame < 1024 || h.max_frame > 1 << 30 {
            return Err((
                "hub.max_frame",
                format!("{} is outside 1024..=1073741824", h.max_frame),
            ));
        }
        if h.io_threads == 0 || h.io_threads > 64 {
            return Err((
                "hub.io_threads",
                format!("{} is outside 1..=64", h.io_threads),
            ));
        }
        for (key, v) in [
            ("hub.subscriber_queue", h.subscriber_queue),
            ("hub.subscriber_queue_bytes", h.subscriber_queue_bytes),
            ("hub.control_queue", h.control_queue),
            ("hub.service_inflight", h.service_inflight),
        ] {
            if v == 0 {
                return Err((key, "must be at least 1".into()));
            }
        }
        if self.ticks.fast_ms == 0 {
            return Err(("ticks.fast_ms", "must be at least 1".into()));
        }
        if self.ticks.slow_ms < self.ticks.fast_ms {
            return Err((
                "ticks.slow_ms",
                format!("{} is shorter than ticks.fast_ms", self.ticks.slow_ms),
            ));
        }
        Ok(())
    }

    /// The Unix socket path, resolved against the data directory; `None` if disabled.
    pub fn unix_socket(&self) -> Option<PathBuf> {
        (!self.server.flow_unix.is_empty())
            .then(|| self.server.data_dir.join(&self.server.flow_unix))
    }

    /// A module's parameters as JSON, with `enabled` defaulting to true.
    pub fn module(&self, name: &str) -> serde_json::Value {
        let table = self.modules.get(name).cloned().unwrap_or_default();
        serde_json::to_value(table).unwrap_or(serde_json::Value::Null)
    }

    /// Whether a module is switched on (`[modules.NAME] enabled = false` turns it off).
    pub fn module_enabled(&self, name: &str) -> bool {
        self.modules
            .get(name)
            .and_then(|t| t.get("enabled"))
            .and_then(toml::Value::as_bool)
            .unwrap_or(true)
    }
}

fn parse_table(file: &str, text: &str) -> Result<toml::Table, ConfigError> {
    text.parse::<toml::Table>().map_err(|e| {
        let line = e
            .span()
            .map(|s| text[..s.start.min(text.len())].lines().count().max(1));
        ConfigError {
            file: file.into(),
            key: line
                .map(|l| format!("line {l}"))
                .unwrap_or_else(|| "-".into()),
            reason: e.message().to_string(),
        }
    })
}

/// Deep-merges `top` into `base`: tables merge, other values replace.
fn overlay(base: &mut toml::Table, top: toml::Table) {
    for (k, v) in top {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(t)) => overlay(b, t),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load_text(text: &str) -> Result<Config, ConfigError> {
        let path =
            std::env::temp_dir().join(format!("cfg-{}-{}.toml", std::process::id(), text.len()));
        std::fs::write(&path, text).expect("write");
        let r = Config::load(Some(&path));
        let _ = std::fs::remove_file(&path);
        r
    }

    #[test]
    fn embedded_defaults_load() {
        let c = Config::load(None).expect("defaults");
        assert_eq!(c.server.http, "127.0.0.1:8080");
        assert_eq!(c.ticks.fast_ms, 10);
    }

    #[test]
    fn overlay_keeps_other_defaults() {
        let c = load_text("[hub]\nsubscriber_queue = 8\n").expect("load");
        assert_eq!(c.hub.subscriber_queue, 8);
        assert_eq!(c.hub.control_queue, 4096);
    }

    #[test]
    fn errors_name_file_key_and_reason() {
        let e = load_text("[hub]\nmax_frame = \"big\"\n").expect_err("type error");
        assert_eq!(e.key, "hub.max_frame");
        assert!(e.to_string().contains(".toml: hub.max_frame: "), "{e}");
        let e = load_text("[hub]\nmax_frme = 5\n").expect_err("unknown key");
        assert!(e.reason.contains("max_frme"), "{e}");
        let e = load_text("[ticks]\nslow_ms = 1\n").expect_err("semantic");
        assert_eq!(e.key, "ticks.slow_ms");
        let e = load_text("[server]\nhttp = \"nowhere\"\n").expect_err("address");
        assert_eq!(e.key, "server.http");
        let e = load_text("[server\n").expect_err("syntax");
        assert_eq!(e.key, "line 1");
    }
}
