//! Parsing of hub addresses: `tcp://HOST:PORT`, `unix:PATH`, `ws://HOST:PORT/flow`, `serial:PATH?baud=N`,
//! `udp://HOST:PORT`.

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
    /// A serial line (or a pseudo-terminal) the hub serves, at `baud` (default 115200).
    Serial {
        path: PathBuf,
        baud: u32,
    },
    /// `host:port` of the hub's UDP edge.
    Udp(String),
}

/// The baud rate of a `serial:` address that names none.
pub const DEFAULT_BAUD: u32 = 115_200;

impl FromStr for FlowAddr {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if let Some(rest) = s.strip_prefix("tcp://") {
            if rest.is_empty() || !rest.contains(':') {
                return Err(format!("{s:?}: expected tcp://HOST:PORT"));
            }
            Ok(FlowAddr::Tcp(rest.trim_end_matches('/').to_string()))
        } else if let Some(rest) = s.strip_prefix("udp://") {
            let rest = rest.trim_end_matches('/');
            match rest.rsplit_once(':') {
                Some((host, port)) if !host.is_empty() && port.parse::<u16>().is_ok() => {
                    Ok(FlowAddr::Udp(rest.to_string()))
                }
                _ => Err(format!("{s:?}: expected udp://HOST:PORT")),
            }
        } else if let Some(rest) = s.strip_prefix("unix:") {
            let path = rest.trim_start_matches("//");
            if path.is_empty() {
                return Err(format!("{s:?}: expected unix:PATH"));
            }
            Ok(FlowAddr::Unix(PathBuf::from(path)))
        } else if let Some(rest) = s.strip_prefix("serial:") {
            let (path, query) = rest.split_once('?').unwrap_or((rest, ""));
            let path = path.trim_start_matches("//");
            if path.is_empty() {
                return Err(format!("{s:?}: expected serial:PATH?baud=N"));
            }
            let mut baud = DEFAULT_BAUD;
            for pair in query.split('&').filter(|p| !p.is_empty()) {
                match pair.split_once('=') {
                    Some(("baud", n)) => {
                        baud = n
                            .parse()
                            .ok()
                            .filter(|&b: &u32| b > 0)
                            .ok_or_else(|| format!("{s:?}: baud must be a positive number"))?;
                    }
                    _ => return Err(format!("{s:?}: unknown option {pair:?} (only baud=N)")),
                }
            }
            Ok(FlowAddr::Serial {
                path: PathBuf::from(path),
                baud,
            })
        } else if s.starts_with("ws://") || s.starts_with("wss://") {
            Ok(FlowAddr::Ws(s.to_string()))
        } else if s.contains(':') && !s.contains('/') {
            Ok(FlowAddr::Tcp(s.to_string()))
        } else {
            Err(format!(
                "{s:?}: expected tcp://HOST:PORT, unix:PATH, ws://HOST:PORT/flow, serial:PATH?baud=N or udp://HOST:PORT"
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
            FlowAddr::Serial { path, baud } => write!(f, "serial:{}?baud={baud}", path.display()),
            FlowAddr::Udp(hp) => write!(f, "udp://{hp}"),
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
        assert_eq!(
            "serial:/dev/ttyUSB0?baud=9600".parse(),
            Ok(FlowAddr::Serial {
                path: "/dev/ttyUSB0".into(),
                baud: 9600
            })
        );
        assert_eq!(
            "serial:/dev/pts/3".parse(),
            Ok(FlowAddr::Serial {
                path: "/dev/pts/3".into(),
                baud: DEFAULT_BAUD
            })
        );
        assert!("serial:/dev/x?baud=0".parse::<FlowAddr>().is_err());
        assert!("serial:/dev/x?parity=odd".parse::<FlowAddr>().is_err());
        assert!("serial:".parse::<FlowAddr>().is_err());
        assert_eq!(
            "udp://127.0.0.1:9000".parse(),
            Ok(FlowAddr::Udp("127.0.0.1:9000".into()))
        );
        assert_eq!(
            "udp://[::1]:9000".parse(),
            Ok(FlowAddr::Udp("[::1]:9000".into()))
        );
        assert_eq!(
            FlowAddr::Udp("robot.local:9001".into()).to_string(),
            "udp://robot.local:9001"
        );
        assert!("udp://".parse::<FlowAddr>().is_err());
        assert!("udp://host".parse::<FlowAddr>().is_err());
        assert!("udp://host:port".parse::<FlowAddr>().is_err());
        assert!("udp://:9000".parse::<FlowAddr>().is_err());
        assert!("bogus".parse::<FlowAddr>().is_err());
        assert!("tcp://".parse::<FlowAddr>().is_err());
    }
}
