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
    pub http: HttpSection,
    pub agent: AgentSection,
    pub federation: FederationSection,
    pub telemetry: TelemetrySection,
    /// `[modules.NAME]` tables, handed to each module as JSON parameters.
    #[serde(default)]
    pub modules: BTreeMap<String, toml::Table>,
    /// Where the configuration came from (the user file, or the embedded defaults), for error messages.
    #[serde(skip)]
    pub source: String,
    /// The `[modules.NAME]` sections the user's file names (the embedded defaults configure every module of
    /// robot-agent; a binary with fewer modules ignores those, but not a section the user wrote).
    #[serde(skip)]
    pub file_modules: Vec<String>,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ServerSection {
    pub http: String,
    pub flow_tcp: String,
    /// FlowProtocol over UDP (`net/udp.rs`); "" (the default) leaves it off.
    pub flow_udp: String,
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
    pub login_timeout_ms: u64,
    pub max_unauthenticated: usize,
    /// Places among the strangers one address may hold (`admission.rs`).
    pub max_unauthenticated_per_address: usize,
    /// How long a logged-in client may take to finish a frame it has begun.
    pub frame_timeout_ms: u64,
    /// Shared memory for clients on the Unix socket (docs/protocol.md, "Shared memory").
    pub shm: bool,
    /// Payloads from this many bytes go by reference.
    pub shm_threshold: u32,
    /// Slots in each segment.
    pub shm_slots: u32,
    /// Slots one subscriber may hold at once.
    pub shm_held: usize,
    /// Segments one channel may have.
    pub shm_segments_per_channel: usize,
    /// `[[hub.serial]]`: serial lines (or pseudo-terminals) the hub serves a satellite on, one each.
    #[serde(default)]
    pub serial: Vec<SerialLine>,
}

/// One serial line the hub serves (`net/serial.rs`): opened at start, reopened whenever it fails or goes away.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SerialLine {
    pub path: PathBuf,
    #[serde(default = "default_baud")]
    pub baud: u32,
}

fn default_baud() -> u32 {
    flow::transport::addr::DEFAULT_BAUD
}

/// `[http]`: who may use the page and the HTTP API (docs/security.md).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct HttpSection {
    /// Host names the page may be opened under besides `localhost`, loopback addresses and the address a client
    /// connected to.
    pub allowed_hosts: Vec<String>,
    /// No credential asked while the HTTP server listens on loopback only.
    pub open_on_loopback: bool,
    /// How long a page session cookie stays valid.
    pub cookie_days: u64,
    /// `"off"`: plain HTTP; `"self-signed"`: HTTPS with a certificate generated once into the data directory;
    /// `"files"`: HTTPS with `tls_cert` and `tls_key`.
    pub tls: String,
    /// PEM certificate chain and private key for `tls = "files"` (relative paths are inside data_dir).
    pub tls_cert: String,
    pub tls_key: String,
    /// How long a connection may take to send a request's headers, and may stay idle between requests (ms).
    pub header_timeout_ms: u64,
    /// HTTP connections served at once (those that showed no credential also count among the strangers).
    pub max_connections: usize,
}

impl HttpSection {
    /// Whether the page is served over HTTPS.
    pub fn tls_on(&self) -> bool {
        self.tls != "off"
    }
}

/// `[agent]`: what the application running on the hub is about, read by its modules (the hub itself ignores it).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AgentSection {
    /// The language the agent converses in, as an ISO 639-1 code; the application checks that it knows it.
    pub language: String,
    /// The knowledge folder the agent answers from (Markdown and text files, docs/knowledge.md); a relative path is
    /// taken from the working directory; "" for none.
    #[serde(default)]
    pub knowledge: String,
}

/// `[telemetry]`: OpenTelemetry traces of each conversational turn (docs/telemetry.md).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TelemetrySection {
    /// The OTLP/HTTP collector (`http://HOST:4318`); "" leaves telemetry to the `OTEL_*` variables, off unless they
    /// name one.
    pub otlp: String,
}

/// `[federation]`: this hub on a Zenoh network with other hubs and Zenoh clients (docs/federation.md).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FederationSection {
    pub enabled: bool,
    /// This hub's name in key expressions; empty: the machine's host name.
    pub name: String,
    /// The first chunks of every key expression of the federation.
    pub prefix: String,
    /// `"peer"` or `"client"` (a client reaches the others through the routers or peers it connects to).
    pub mode: String,
    /// Zenoh endpoints to connect to (`tcp/HOST:PORT`), retried in the background until they answer.
    pub connect: Vec<String>,
    /// Zenoh endpoints to listen on (`tcp/HOST:PORT`).
    pub listen: Vec<String>,
    /// Zenoh's multicast scouting (discovery of peers on the LAN); off unless asked for.
    pub multicast_scouting: bool,
    /// Globs of local channel names offered to the other hubs.
    pub export: Vec<String>,
    /// Globs of remote channel names made local here.
    pub import: Vec<String>,
    /// Zenoh user/password authentication: the user this hub presents, ...
    pub user: String,
    /// ... the file holding its password (relative paths are inside data_dir), ...
    pub password_file: String,
    /// ... and the file of `user:password` lines that peers connecting here must match.
    pub users_file: String,
    /// How long a silent peer is kept before its channels are taken away (ms).
    pub lease_ms: u64,
    /// The longest a call to a remote service may take (the caller's own timeout applies when shorter).
    pub call_timeout_ms: u64,
    /// Per imported stream: messages queued towards the local hub before the oldest is dropped.
    pub queue: usize,
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
        let mut file_modules = Vec::new();
        let file = match path {
            Some(p) => {
                let name = p.display().to_string();
                let text = std::fs::read_to_string(p).map_err(|e| ConfigError {
                    file: name.clone(),
                    key: "-".into(),
                    reason: format!("cannot read: {e}"),
                })?;
                let table = parse_table(&name, &text)?;
                file_modules = table
                    .get("modules")
                    .and_then(toml::Value::as_table)
                    .map(|t| t.keys().cloned().collect())
                    .unwrap_or_default();
                overlay(&mut merged, table);
                name
            }
            None => "<embedded default.toml>".to_string(),
        };
        let mut config: Config = serde_path_to_error::deserialize(toml::Value::Table(merged))
            .map_err(|e| ConfigError {
                file: file.clone(),
                key: e.path().to_string(),
                reason: e.inner().to_string(),
            })?;
        config.validate().map_err(|(key, reason)| ConfigError {
            file: file.clone(),
            key: key.into(),
            reason,
        })?;
        config.source = file;
        config.file_modules = file_modules;
        Ok(config)
    }

    /// An error about `key` of this configuration, naming its file.
    pub fn error(&self, key: impl Into<String>, reason: impl Into<String>) -> ConfigError {
        ConfigError {
            file: self.source.clone(),
            key: key.into(),
            reason: reason.into(),
        }
    }

    /// Turns a module's own message about a section (`[modules.NAME] KEY: REASON`, or any text, taken to be
    /// about `[modules.NAME]`) into an error naming the file, the key and the reason.
    pub fn module_error(&self, name: &str, message: &str) -> ConfigError {
        let Some(rest) = message.strip_prefix("[modules.") else {
            return self.error(format!("modules.{name}"), message);
        };
        // `[modules.tts.behaviour] blink_min_ms: ...` or `[modules.video_y] quality: ...`
        let (section, rest) = rest.split_once(']').unwrap_or((name, rest));
        let rest = rest.trim_start();
        match rest.split_once(": ") {
            Some((key, reason)) if !key.is_empty() && !key.contains(' ') => {
                self.error(format!("modules.{section}.{key}"), reason)
            }
            _ => self.error(format!("modules.{section}"), rest),
        }
    }

    /// Refuses `[modules.X]` sections of the user's file that name no module in `known`: a misspelt section would
    /// otherwise switch nothing off, silently.
    pub fn check_module_names(&self, known: &[&str]) -> Result<(), ConfigError> {
        match self
            .file_modules
            .iter()
            .find(|k| !known.contains(&k.as_str()))
        {
            None => Ok(()),
            Some(unknown) => Err(self.error(
                format!("modules.{unknown}"),
                format!("no such module (the modules are: {})", known.join(", ")),
            )),
        }
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
        if self.http.open_on_loopback
            && !self
                .server
                .http
                .parse::<SocketAddr>()
                .is_ok_and(|a| a.ip().is_loopback())
        {
            return Err((
                "http.open_on_loopback",
                format!(
                    "true is only allowed while server.http is a loopback address, not {:?}: beyond loopback the page needs its credential",
                    self.server.http
                ),
            ));
        }
        if !(1..=365).contains(&self.http.cookie_days) {
            return Err((
                "http.cookie_days",
                format!("{} is outside 1..=365", self.http.cookie_days),
            ));
        }
        addr("server.flow_tcp", &self.server.flow_tcp, true)?;
        addr("server.flow_udp", &self.server.flow_udp, true)?;
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
        if h.shm_threshold < 4096 || h.shm_threshold as usize > h.max_frame {
            return Err((
                "hub.shm_threshold",
                format!("{} is outside 4096..=hub.max_frame", h.shm_threshold),
            ));
        }
        if h.shm_slots == 0 || h.shm_slots > flow::shm::layout::MAX_SLOTS {
            return Err((
                "hub.shm_slots",
                format!(
                    "{} is outside 1..={}",
                    h.shm_slots,
                    flow::shm::layout::MAX_SLOTS
                ),
            ));
        }
        for (key, v) in [
            ("hub.shm_held", h.shm_held),
            ("hub.shm_segments_per_channel", h.shm_segments_per_channel),
            ("hub.subscriber_queue", h.subscriber_queue),
            ("hub.subscriber_queue_bytes", h.subscriber_queue_bytes),
            ("hub.control_queue", h.control_queue),
            ("hub.service_inflight", h.service_inflight),
            ("hub.max_unauthenticated", h.max_unauthenticated),
            (
                "hub.max_unauthenticated_per_address",
                h.max_unauthenticated_per_address,
            ),
            ("http.max_connections", self.http.max_connections),
        ] {
            if v == 0 {
                return Err((key, "must be at least 1".into()));
            }
        }
        for line in &h.serial {
            if line.path.as_os_str().is_empty() {
                return Err(("hub.serial.path", "must name a device".into()));
            }
            if line.baud == 0 {
                return Err((
                    "hub.serial.baud",
                    format!("{}: must be at least 1", line.path.display()),
                ));
            }
        }
        if !(100..=600_000).contains(&h.login_timeout_ms) {
            return Err((
                "hub.login_timeout_ms",
                format!("{} is outside 100..=600000", h.login_timeout_ms),
            ));
        }
        if !(1000..=3_600_000).contains(&h.frame_timeout_ms) {
            return Err((
                "hub.frame_timeout_ms",
                format!("{} is outside 1000..=3600000", h.frame_timeout_ms),
            ));
        }
        if !(500..=600_000).contains(&self.http.header_timeout_ms) {
            return Err((
                "http.header_timeout_ms",
                format!("{} is outside 500..=600000", self.http.header_timeout_ms),
            ));
        }
        match self.http.tls.as_str() {
            "off" | "self-signed" => {}
            "files" => {
                for (key, v) in [
                    ("http.tls_cert", &self.http.tls_cert),
                    ("http.tls_key", &self.http.tls_key),
                ] {
                    if v.is_empty() {
                        return Err((key, "tls = \"files\" needs a PEM file here".into()));
                    }
                }
            }
            other => {
                return Err((
                    "http.tls",
                    format!("{other:?} is not one of \"off\", \"self-signed\", \"files\""),
                ));
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
        flow_telemetry::traces_endpoint(Some(("telemetry.otlp", &self.telemetry.otlp)), |_| None)
            .map_err(|e| ("telemetry.otlp", e.reason()))?;
        self.federation.validate()
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

impl FederationSection {
    /// This hub's name on the federation: `name`, or the host name when it is empty.
    pub fn hub_name(&self) -> String {
        if !self.name.is_empty() {
            return self.name.clone();
        }
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .or_else(|_| std::fs::read_to_string("/etc/hostname"))
            .unwrap_or_default();
        let host: String = host
            .trim()
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '.' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        if host.is_empty() { "hub".into() } else { host }
    }

    fn validate(&self) -> Result<(), (&'static str, String)> {
        use crate::zenoh_names::{check_endpoint, check_hub_name, check_literal};
        if !self.enabled {
            return Ok(());
        }
        check_hub_name(&self.hub_name()).map_err(|e| ("federation.name", e.to_string()))?;
        check_literal(&self.prefix).map_err(|e| ("federation.prefix", e.to_string()))?;
        match self.mode.as_str() {
            "peer" => {}
            "client" if self.connect.is_empty() => {
                return Err((
                    "federation.connect",
                    "a client must connect to at least one peer or router".into(),
                ));
            }
            "client" => {}
            other => {
                return Err((
                    "federation.mode",
                    format!("unknown mode {other:?} (expected \"peer\" or \"client\")"),
                ));
            }
        }
        for (key, list) in [
            ("federation.connect", &self.connect),
            ("federation.listen", &self.listen),
        ] {
            for endpoint in list {
                check_endpoint(endpoint).map_err(|e| (key, e))?;
            }
        }
        for (key, list) in [
            ("federation.export", &self.export),
            ("federation.import", &self.import),
        ] {
            for pattern in list {
                glob::Pattern::new(pattern)
                    .map_err(|e| (key, format!("{pattern:?} is not a glob: {e}")))?;
            }
        }
        let auth = [&self.user, &self.password_file];
        if auth.iter().any(|v| v.is_empty()) && auth.iter().any(|v| !v.is_empty()) {
            return Err((
                "federation.user",
                "user and password_file go together: set both or neither".into(),
            ));
        }
        if !(500..=600_000).contains(&self.lease_ms) {
            return Err((
                "federation.lease_ms",
                format!("{} is outside 500..=600000", self.lease_ms),
            ));
        }
        if !(1..=3_600_000).contains(&self.call_timeout_ms) {
            return Err((
                "federation.call_timeout_ms",
                format!("{} is outside 1..=3600000", self.call_timeout_ms),
            ));
        }
        if self.queue == 0 {
            return Err(("federation.queue", "must be at least 1".into()));
        }
        Ok(())
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
    fn module_messages_become_file_key_and_reason() {
        let c = load_text("[hub]\nsubscriber_queue = 8\n").expect("load");
        let e = c.module_error(
            "browser",
            "[modules.video_y] quality: 500 is outside 1..=100",
        );
        assert_eq!(e.key, "modules.video_y.quality");
        assert_eq!(e.reason, "500 is outside 1..=100");
        assert!(e.file.ends_with(".toml"), "{}", e.file);
        let e = c.module_error("tts", "[modules.tts.behaviour] blink_min_ms: too long");
        assert_eq!(e.key, "modules.tts.behaviour.blink_min_ms");
        let e = c.module_error("brain", "program: config/x.tr: no such file");
        assert_eq!(e.key, "modules.brain");
        assert_eq!(e.reason, "program: config/x.tr: no such file");
    }

    #[test]
    fn unknown_module_sections_are_refused() {
        let c = load_text("[modules.bogus]\nenabled = false\n").expect("load");
        let known = ["audio_fft", "brain", "browser", "tts", "video_y", "vision"];
        let e = c.check_module_names(&known).expect_err("bogus");
        assert_eq!(e.key, "modules.bogus");
        assert!(e.reason.contains("brain, browser, tts"), "{e}");
        assert!(
            c.check_module_names(&["bogus"]).is_ok(),
            "the defaults' sections are not the user's"
        );
        assert!(
            Config::load(None)
                .expect("defaults")
                .check_module_names(&["browser", "video_y", "audio_fft", "vision", "brain", "tts"])
                .is_ok()
        );
    }

    #[test]
    fn open_on_loopback_is_refused_beyond_loopback() {
        let e = load_text("[server]\nhttp = \"0.0.0.0:8080\"\n[http]\nopen_on_loopback = true\n")
            .expect_err("open beyond loopback");
        assert_eq!(e.key, "http.open_on_loopback");
        assert!(load_text("[http]\nopen_on_loopback = true\n").is_ok());
    }

    #[test]
    fn a_collector_that_traces_cannot_reach_is_refused_at_start_by_its_key() {
        assert!(load_text("[telemetry]\notlp = \"http://127.0.0.1:4318\"\n").is_ok());
        for (url, words) in [
            ("https://collector:4318", "HTTPS"),
            ("collector:4318", "not an http:// URL"),
        ] {
            let e = load_text(&format!("[telemetry]\notlp = \"{url}\"\n")).expect_err(url);
            assert_eq!(e.key, "telemetry.otlp", "{url}: {e}");
            assert!(e.reason.contains(words), "{url}: {e}");
        }
    }

    #[test]
    fn federation_mistakes_are_named_by_their_key() {
        let on = "[federation]\nenabled = true\nname = \"a\"\n";
        assert!(load_text(on).is_ok());
        assert!(
            load_text("[federation]\nmode = \"bogus\"\n").is_ok(),
            "a switched-off section is not checked"
        );
        for (extra, key, words) in [
            ("mode = \"router\"\n", "federation.mode", "unknown mode"),
            ("mode = \"client\"\n", "federation.connect", "at least one"),
            (
                "connect = [\"udp/1.2.3.4:7447\"]\n",
                "federation.connect",
                "only tcp",
            ),
            (
                "listen = [\"tcp/127.0.0.1\"]\n",
                "federation.listen",
                "HOST:PORT",
            ),
            ("export = [\"[\"]\n", "federation.export", "not a glob"),
            ("user = \"a\"\n", "federation.user", "go together"),
            ("prefix = \"a/*\"\n", "federation.prefix", "wildcard"),
            ("lease_ms = 10\n", "federation.lease_ms", "outside"),
            ("queue = 0\n", "federation.queue", "at least 1"),
        ] {
            let e = load_text(&format!("{on}{extra}")).expect_err(extra);
            assert_eq!(e.key, key, "{extra}: {e}");
            assert!(e.reason.contains(words), "{extra}: {e}");
        }
        let e = load_text("[federation]\nenabled = true\nname = \"a/b\"\n").expect_err("name");
        assert_eq!(e.key, "federation.name");
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
