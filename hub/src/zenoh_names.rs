//! The names `[federation]` hands to Zenoh, checked before anything starts: the key prefix, the hub's name, channel
//! names and endpoints. A leaf, so that the configuration checks them at load and the federation when it builds keys,
//! without either importing the other.

use std::str::FromStr;

/// Why a name cannot be used in a key expression.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    #[error("{0:?} is empty or has an empty part between slashes")]
    EmptyChunk(String),
    #[error("{0:?} contains one of the Zenoh wildcard characters * $ # ?")]
    Wildcard(String),
    #[error("{0:?} has a part starting with @, which Zenoh reserves")]
    Verbatim(String),
}

/// Checks that `text` is usable as one or more literal chunks of a key expression.
pub fn check_literal(text: &str) -> Result<(), KeyError> {
    if text.contains(['*', '$', '#', '?']) {
        return Err(KeyError::Wildcard(text.to_string()));
    }
    for chunk in text.split('/') {
        if chunk.is_empty() {
            return Err(KeyError::EmptyChunk(text.to_string()));
        }
        if chunk.starts_with('@') {
            return Err(KeyError::Verbatim(text.to_string()));
        }
    }
    Ok(())
}

/// Checks a hub name: one literal chunk (no slash).
pub fn check_hub_name(name: &str) -> Result<(), KeyError> {
    if name.contains('/') {
        return Err(KeyError::EmptyChunk(format!(
            "{name} (a hub name is one part, without /)"
        )));
    }
    check_literal(name)
}

/// Checks a Zenoh endpoint of the configuration, so that a typo stops the hub at start with the key and the reason
/// instead of failing to connect later. Accepts `tcp/HOST:PORT` (the only transport this hub builds), with Zenoh's
/// own syntax check.
pub fn check_endpoint(text: &str) -> Result<(), String> {
    let parsed = zenoh::config::EndPoint::from_str(text)
        .map_err(|e| format!("{text:?} is not a Zenoh endpoint: {e}"))?;
    let locator = parsed.to_locator();
    if locator.protocol().as_str() != "tcp" {
        return Err(format!(
            "{text:?}: only tcp/HOST:PORT endpoints are supported, not {}",
            locator.protocol().as_str()
        ));
    }
    let address = locator.address().as_str();
    let port_ok = address
        .rsplit_once(':')
        .is_some_and(|(host, port)| !host.is_empty() && port.parse::<u16>().is_ok());
    if !port_ok {
        return Err(format!("{text:?}: expected tcp/HOST:PORT"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_that_zenoh_would_read_as_patterns_are_refused() {
        assert!(check_literal("Robot.audio").is_ok());
        assert!(check_literal("robot/arm").is_ok());
        assert!(matches!(check_literal("a*"), Err(KeyError::Wildcard(_))));
        assert!(matches!(check_literal("a$b"), Err(KeyError::Wildcard(_))));
        assert!(matches!(
            check_literal("a//b"),
            Err(KeyError::EmptyChunk(_))
        ));
        assert!(matches!(check_literal("/a"), Err(KeyError::EmptyChunk(_))));
        assert!(matches!(check_literal("a/@b"), Err(KeyError::Verbatim(_))));
        assert!(check_hub_name("a/b").is_err());
        assert!(check_hub_name("hub-a").is_ok());
    }

    #[test]
    fn tcp_endpoints_pass_and_others_are_named() {
        assert!(check_endpoint("tcp/127.0.0.1:7447").is_ok());
        assert!(check_endpoint("tcp/[::1]:7447").is_ok());
        assert!(check_endpoint("tcp/robot.local:7447").is_ok());
        let e = check_endpoint("udp/127.0.0.1:7447").expect_err("udp");
        assert!(e.contains("only tcp"), "{e}");
        let e = check_endpoint("tcp/127.0.0.1").expect_err("no port");
        assert!(e.contains("HOST:PORT"), "{e}");
        assert!(check_endpoint("127.0.0.1:7447").is_err());
    }
}
