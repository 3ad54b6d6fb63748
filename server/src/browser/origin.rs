//! Which requests come from the server's own page: the `Host` must name this server and `Origin` must match it.
//!
//! Comparing `Origin` with `Host` stops a cross-site page (its Origin is its own site). That alone would let a
//! DNS-rebinding site through (its name resolves to us, so Host and Origin agree), so `Host` must also be a name
//! this server answers to: a loopback name, an IP literal (rebinding needs a DNS name), or one configured.

/// The host names a server accepts besides IP literals and loopback names.
#[derive(Debug, Clone, Default)]
pub struct OriginPolicy {
    pub extra_hosts: Vec<String>,
}

impl OriginPolicy {
    /// Whether a request with these `Host` and `Origin` headers comes from our own page. `origin` is `None` when
    /// the header is missing; `require_origin` says whether that is acceptable (it is not for WebSockets).
    pub fn allows(&self, host: Option<&str>, origin: Option<&str>, require_origin: bool) -> bool {
        let Some(host) = host else { return false };
        if !self.host_is_ours(host) {
            return false;
        }
        match origin {
            None => !require_origin,
            Some(origin) => {
                let rest = origin
                    .strip_prefix("http://")
                    .or_else(|| origin.strip_prefix("https://"));
                rest.is_some_and(|authority| authority.eq_ignore_ascii_case(host))
            }
        }
    }

    fn host_is_ours(&self, host: &str) -> bool {
        let name = host_name(host);
        if name.eq_ignore_ascii_case("localhost") || name.parse::<std::net::IpAddr>().is_ok() {
            return true;
        }
        self.extra_hosts
            .iter()
            .any(|h| h.eq_ignore_ascii_case(name))
    }
}

/// The name part of a `Host` header value (`[::1]:8080` -> `::1`, `localhost:8080` -> `localhost`).
fn host_name(host: &str) -> &str {
    if let Some(rest) = host.strip_prefix('[') {
        return rest.split(']').next().unwrap_or(rest);
    }
    match host.rsplit_once(':') {
        Some((name, port)) if port.chars().all(|c| c.is_ascii_digit()) => name,
        _ => host,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_page_is_allowed() {
        let p = OriginPolicy::default();
        assert!(p.allows(Some("127.0.0.1:8080"), Some("http://127.0.0.1:8080"), true));
        assert!(p.allows(Some("localhost:8080"), Some("http://localhost:8080"), true));
        assert!(p.allows(Some("[::1]:8080"), Some("http://[::1]:8080"), true));
        assert!(p.allows(
            Some("192.168.1.20:8080"),
            Some("https://192.168.1.20:8080"),
            true
        ));
    }

    #[test]
    fn cross_site_and_rebinding_pages_are_refused() {
        let p = OriginPolicy::default();
        assert!(!p.allows(Some("127.0.0.1:8080"), Some("http://evil.example"), true));
        assert!(!p.allows(Some("127.0.0.1:8080"), Some("http://127.0.0.1:9999"), true));
        assert!(!p.allows(Some("127.0.0.1:8080"), Some("null"), true));
        assert!(!p.allows(Some("127.0.0.1:8080"), None, true));
        assert!(!p.allows(None, Some("http://127.0.0.1:8080"), true));
        // DNS rebinding: Host and Origin agree, but the name is not ours.
        assert!(!p.allows(
            Some("evil.example:8080"),
            Some("http://evil.example:8080"),
            true
        ));
    }

    #[test]
    fn configured_names_and_originless_requests() {
        let p = OriginPolicy {
            extra_hosts: vec!["robot.local".into()],
        };
        assert!(p.allows(
            Some("robot.local:8080"),
            Some("http://robot.local:8080"),
            true
        ));
        assert!(p.allows(Some("127.0.0.1:8080"), None, false));
    }
}
