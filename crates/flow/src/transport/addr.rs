//! Parsing of hub addresses: `tcp://HOST:PORT`, `unix:PATH`, `ws://HOST:PORT/flow`.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

/// Where a hub listens.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FlowAddr {
    /// `host:port`.
    Tcp(String),
    Unix(PathBuf),
    /// A full `ws://` URL.
    Ws(String),
}

impl FromStr for FlowAddr {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if let Some(rest) = s.strip_prefix("tcp://") {
            if rest.is_empty() || !rest.contains(':') {
                return Err(format!("{s:?}: expected tcp://HOST:PORT"));
            }
            Ok(FlowAddr::Tcp(rest.trim_end_matches('/').to_string()))
        } else if let Some(rest) = s.strip_prefix("unix:") {
            let path = rest.trim_start_matches("//");
            if path.is_empty() {
                return Err(format!("{s:?}: expected unix:PATH"));
            }
            Ok(FlowAddr::Unix(PathBuf::from(path)))
        } else if s.starts_with("ws://") || s.starts_with("wss://") {
            Ok(FlowAddr::Ws(s.to_string()))
        } else if s.contains(':') && !s.contains('/') {
            Ok(FlowAddr::Tcp(s.to_string()))
        } else {
            Err(format!(
                "{s:?}: expected tcp://HOST:PORT, unix:PATH or ws://HOST:PORT/flow"
            ))
        }
    }
}

impl fmt::Display for FlowAddr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FlowAddr::Tcp(hp) => write!(f, "tcp://{hp}"),
            FlowAddr::Unix(p) => write!(f, "unix:{}", p.display()),
            FlowAddr::Ws(url) => f.write_str(url),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_each_form() {
        assert_eq!(
            "tcp://127.0.0.1:9000".parse(),
            Ok(FlowAddr::Tcp("127.0.0.1:9000".into()))
        );
        assert_eq!(
            "127.0.0.1:9000".parse(),
            Ok(FlowAddr::Tcp("127.0.0.1:9000".into()))
        );
        assert_eq!(
            "unix:/tmp/x.sock".parse(),
            Ok(FlowAddr::Unix("/tmp/x.sock".into()))
        );
        assert_eq!(
            "ws://127.0.0.1:8080/flow".parse(),
            Ok(FlowAddr::Ws("ws://127.0.0.1:8080/flow".into()))
        );
        assert!("bogus".parse::<FlowAddr>().is_err());
        assert!("tcp://".parse::<FlowAddr>().is_err());
    }
}
