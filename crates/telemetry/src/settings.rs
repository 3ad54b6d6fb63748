//! Where spans go, from the configuration and the standard `OTEL_*` variables; pure, so every rule is tested.
//! Telemetry is off unless a collector is named: `[telemetry] otlp` (robot-agent), `--otlp` (satellites), or
//! `OTEL_EXPORTER_OTLP_TRACES_ENDPOINT` / `OTEL_EXPORTER_OTLP_ENDPOINT`; `OTEL_SDK_DISABLED=true` or
//! `OTEL_TRACES_EXPORTER=none` turn it off whatever is named.

/// Why a collector address was refused: where it was named (`origin`) and what is wrong with it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SettingsError {
    #[error("{origin}: {}", self.reason())]
    Https { origin: String, url: String },
    #[error("{origin}: {}", self.reason())]
    NotHttp { origin: String, url: String },
}

impl SettingsError {
    /// What is wrong, without where it was named (a configuration error names its key itself).
    pub fn reason(&self) -> String {
        match self {
            SettingsError::Https { url, .. } => format!(
                "{url:?} is HTTPS; traces are sent over plain HTTP (OTLP/HTTP, port 4318): run the collector on \
                 this machine or the LAN, or put a local collector in front of a remote one"
            ),
            SettingsError::NotHttp { url, .. } => format!(
                "{url:?} is not an http:// URL of an OTLP/HTTP collector (e.g. http://127.0.0.1:4318)"
            ),
        }
    }
}

/// The OTLP/HTTP traces URL to export to, or `None` when telemetry is off. `configured` is the program's own
/// setting (it wins over the environment, as OpenTelemetry's programmatic configuration does); `env` looks a
/// variable up.
pub fn traces_endpoint(
    configured: Option<(&str, &str)>,
    env: impl Fn(&str) -> Option<String>,
) -> Result<Option<String>, SettingsError> {
    let set = |name: &str| {
        env(name)
            .map(|v| v.trim().to_owned())
            .filter(|v| !v.is_empty())
    };
    if set("OTEL_SDK_DISABLED").is_some_and(|v| v.eq_ignore_ascii_case("true"))
        || set("OTEL_TRACES_EXPORTER").is_some_and(|v| v.eq_ignore_ascii_case("none"))
    {
        return Ok(None);
    }
    let (origin, url, base) =
        if let Some((origin, url)) = configured.filter(|(_, u)| !u.trim().is_empty()) {
            (origin.to_owned(), url.trim().to_owned(), true)
        } else if let Some(url) = set("OTEL_EXPORTER_OTLP_TRACES_ENDPOINT") {
            ("OTEL_EXPORTER_OTLP_TRACES_ENDPOINT".to_owned(), url, false)
        } else if let Some(url) = set("OTEL_EXPORTER_OTLP_ENDPOINT") {
            ("OTEL_EXPORTER_OTLP_ENDPOINT".to_owned(), url, true)
        } else {
            return Ok(None);
        };
    if url.starts_with("https://") {
        return Err(SettingsError::Https { origin, url });
    }
    let has_host = url
        .strip_prefix("http://")
        .is_some_and(|rest| !rest.is_empty() && !rest.starts_with('/'));
    if !has_host {
        return Err(SettingsError::NotHttp { origin, url });
    }
    // A base address gets the traces path, as the OTLP exporter specification says for OTEL_EXPORTER_OTLP_ENDPOINT;
    // a signal-specific one is used as it is.
    Ok(Some(if base {
        format!("{}/v1/traces", url.trim_end_matches('/'))
    } else {
        url
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(vars: &[(&'static str, &'static str)]) -> impl Fn(&str) -> Option<String> {
        let vars = vars.to_vec();
        move |name| {
            vars.iter()
                .find(|(k, _)| *k == name)
                .map(|(_, v)| (*v).to_owned())
        }
    }

    const KEY: &str = "[telemetry] otlp";

    #[test]
    fn nothing_named_means_telemetry_is_off() {
        assert_eq!(traces_endpoint(None, env(&[])), Ok(None));
        assert_eq!(traces_endpoint(Some((KEY, "")), env(&[])), Ok(None));
    }

    #[test]
    fn a_base_address_gets_the_traces_path_and_a_signal_address_is_kept() {
        let base = traces_endpoint(Some((KEY, "http://collector:4318")), env(&[]));
        assert_eq!(base, Ok(Some("http://collector:4318/v1/traces".into())));
        let slash = traces_endpoint(Some((KEY, "http://collector:4318/")), env(&[]));
        assert_eq!(slash, Ok(Some("http://collector:4318/v1/traces".into())));
        let from_env = traces_endpoint(
            None,
            env(&[("OTEL_EXPORTER_OTLP_ENDPOINT", "http://c:4318")]),
        );
        assert_eq!(from_env, Ok(Some("http://c:4318/v1/traces".into())));
        let signal = traces_endpoint(
            None,
            env(&[
                ("OTEL_EXPORTER_OTLP_TRACES_ENDPOINT", "http://c:9999/traces"),
                ("OTEL_EXPORTER_OTLP_ENDPOINT", "http://other:4318"),
            ]),
        );
        assert_eq!(signal, Ok(Some("http://c:9999/traces".into())));
    }

    #[test]
    fn the_programs_setting_wins_over_the_environment_and_disabled_wins_over_everything() {
        let vars = [("OTEL_EXPORTER_OTLP_ENDPOINT", "http://env:4318")];
        assert_eq!(
            traces_endpoint(Some((KEY, "http://mine:4318")), env(&vars)),
            Ok(Some("http://mine:4318/v1/traces".into()))
        );
        let off = [
            ("OTEL_SDK_DISABLED", "true"),
            ("OTEL_EXPORTER_OTLP_ENDPOINT", "http://env:4318"),
        ];
        assert_eq!(
            traces_endpoint(Some((KEY, "http://mine:4318")), env(&off)),
            Ok(None)
        );
        assert_eq!(
            traces_endpoint(None, env(&[("OTEL_TRACES_EXPORTER", "none"), vars[0]])),
            Ok(None)
        );
    }

    #[test]
    fn an_address_that_cannot_work_is_refused_naming_where_it_came_from() {
        match traces_endpoint(Some((KEY, "https://collector:4318")), env(&[])) {
            Err(e @ SettingsError::Https { .. }) => assert!(e.to_string().starts_with(KEY)),
            other => panic!("{other:?}"),
        }
        for bad in [
            "collector:4318",
            "http://",
            "grpc://c:4317",
            "http:///v1/traces",
        ] {
            assert!(
                matches!(
                    traces_endpoint(Some((KEY, bad)), env(&[])),
                    Err(SettingsError::NotHttp { .. })
                ),
                "{bad}"
            );
        }
        let env_bad = traces_endpoint(None, env(&[("OTEL_EXPORTER_OTLP_ENDPOINT", "c:4318")]));
        assert!(
            matches!(env_bad, Err(SettingsError::NotHttp { origin, .. }) if origin == "OTEL_EXPORTER_OTLP_ENDPOINT")
        );
    }
}
