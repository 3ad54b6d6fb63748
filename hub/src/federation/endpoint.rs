//! Checks a Zenoh endpoint of the configuration before anything starts, so that a typo stops the hub at start with
//! the key and the reason instead of failing to connect later.

use std::str::FromStr;

/// Accepts `tcp/HOST:PORT` (the only transport this hub builds), with Zenoh's own syntax check.
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
    use super::check_endpoint;

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
