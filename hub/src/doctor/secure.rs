//! The doctor's secure-context check: a browser gives the microphone and camera (getUserMedia) only to a page in a
//! secure context, that is over HTTPS, or over plain HTTP from `localhost` or a loopback address. Given the address
//! a browser will open the page by (`doctor --from ADDRESS`), it says whether that page gets them: HTTPS on, the
//! certificate naming the address, the HTTP address reachable from other machines and the `Host` check letting the
//! name in. Without `--from`, it warns when plain HTTP listens beyond loopback.

use std::collections::BTreeSet;
use std::net::{IpAddr, SocketAddr};

use super::certificate::{self, names_name};
use super::finding::Finding;
use super::ports::resolve;
use crate::config::Config;
use crate::http::tls::machine_names;

/// The facts the secure-context findings are made from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Facts {
    /// `[server] http` as an address (`None` where it does not parse: the port check says so).
    pub http: Option<SocketAddr>,
    /// The certificate, `Off` when HTTPS is off.
    pub tls: certificate::Facts,
    /// `--from` reduced to its host (`robot.local`, `192.168.1.20`), if given.
    pub from: Option<String>,
    /// `[http] allowed_hosts`: the names the page answers to besides `localhost` and the machine's addresses.
    pub allowed_hosts: Vec<String>,
    /// This machine's names and addresses now.
    pub machine: BTreeSet<String>,
}

/// The host of what a user typed for `--from`: without a scheme, path or port, in lower case.
pub fn host_of(text: &str) -> String {
    let text = text.trim();
    let text = text
        .strip_prefix("https://")
        .or_else(|| text.strip_prefix("http://"))
        .unwrap_or(text);
    let authority = text.split('/').next().unwrap_or(text);
    let host = if let Some(rest) = authority.strip_prefix('[') {
        rest.split(']').next().unwrap_or(rest)
    } else if authority.matches(':').count() == 1 {
        authority.split(':').next().unwrap_or(authority)
    } else {
        // No port, or a bare IPv6 address.
        authority
    };
    host.trim_end_matches('.').to_ascii_lowercase()
}

/// Whether a browser counts plain HTTP from `host` as a secure context: `localhost`, a name under it, a loopback
/// address.
pub fn is_loopback(host: &str) -> bool {
    host == "localhost"
        || host.ends_with(".localhost")
        || host.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// Gathers the facts the configuration and `--from` point at.
pub fn gather(config: &Config, from: Option<&str>) -> Facts {
    Facts {
        http: resolve(&config.server.http),
        tls: certificate::gather(config),
        from: from.map(host_of),
        allowed_hosts: config.http.allowed_hosts.clone(),
        machine: machine_names(&config.http.allowed_hosts),
    }
}

const HTTPS_FIX: &str = "serve the page over HTTPS: --https, or [http] tls = \"self-signed\" in the configuration \
                         (docs/deploy.md, \"On a LAN, with HTTPS\"); or open the page on this machine itself, at \
                         http://localhost";

/// The findings for the page's secure context.
pub fn findings(facts: &Facts) -> Vec<Finding> {
    let Some(http) = facts.http else {
        return Vec::new();
    };
    let https = !matches!(facts.tls, certificate::Facts::Off);
    let Some(from) = &facts.from else {
        return vec![without_from(http, https)];
    };
    let scheme = if https { "https" } else { "http" };
    let page = format!("{scheme}://{from}:{}", http.port());
    if is_loopback(from) {
        return vec![Finding::ok(
            "page",
            format!(
                "{page} is a secure context: the page gets the microphone and camera in a browser on this machine"
            ),
        )];
    }
    let mut out = Vec::new();
    if http.ip().is_loopback() {
        out.push(Finding::problem(
            "page",
            format!("the HTTP address {http} listens on loopback only: a browser on another machine cannot open {page}"),
            "listen on the network: --http 0.0.0.0:8443 --https (docs/deploy.md, \"On a LAN, with HTTPS\")",
        ));
    }
    // The `Host` check against DNS rebinding (http/access.rs): an address must be one of the machine's, a name one
    // of `[http] allowed_hosts`.
    if from.parse::<IpAddr>().is_ok() {
        if !facts.machine.contains(from.as_str()) {
            out.push(Finding::warning(
                "page",
                format!(
                    "{from} is none of this machine's addresses: the page answers only to its own addresses (a \
                     forwarded port is refused)"
                ),
                "open the page by this machine's own address, or by a name listed in [http] allowed_hosts",
            ));
        }
    } else if !facts
        .allowed_hosts
        .iter()
        .any(|h| h.eq_ignore_ascii_case(from))
    {
        out.push(Finding::problem(
            "page",
            format!("the page refuses the name {from}: it is not in [http] allowed_hosts (the guard against DNS rebinding)"),
            format!(
                "add it to the configuration: [http] allowed_hosts = [\"{from}\"], then restart robot-agent{}",
                if https { " (its certificate is made for that name too)" } else { "" }
            ),
        ));
    }
    match &facts.tls {
        certificate::Facts::Off => out.push(Finding::problem(
            "page",
            format!(
                "{page} is not a secure context (plain HTTP from another address than localhost): the browser \
                 gives the page no microphone or camera"
            ),
            HTTPS_FIX,
        )),
        certificate::Facts::SelfSigned {
            parsed,
            names,
            wanted,
            ..
        } => {
            let made = matches!(parsed, Some(Ok(_)));
            // The names a certificate has, or will have when the agent makes it at start.
            let named = if made {
                names_name(names, from)
            } else {
                names_name(wanted, from)
            };
            if named {
                out.push(Finding::ok(
                    "page",
                    format!(
                        "{page} is a secure context: the self-signed certificate {} {from} (accept it once in the \
                         browser, comparing its fingerprint)",
                        if made { "names" } else { "the agent makes at start will name" }
                    ),
                ));
            } else if names_name(wanted, from) {
                out.push(Finding::problem(
                    "page",
                    format!(
                        "the self-signed certificate does not name {from}: the browser refuses {page}"
                    ),
                    "restart robot-agent: it makes a new certificate for this machine's names (browsers ask to \
                     accept it again)",
                ));
            } else {
                // A name joins the certificate through allowed_hosts; an address only by being the machine's.
                let fix = if from.parse::<IpAddr>().is_ok() {
                    "open the page by one of this machine's addresses, which the certificate names".to_string()
                } else {
                    format!(
                        "add it to [http] allowed_hosts = [\"{from}\"] and restart robot-agent, or open the page by \
                         an address of this machine"
                    )
                };
                out.push(Finding::problem(
                    "page",
                    format!(
                        "the self-signed certificate does not name {from}, and one made now would not either: the \
                         browser refuses {page}"
                    ),
                    fix,
                ));
            }
        }
        certificate::Facts::Files { .. } => out.push(Finding::ok(
            "page",
            format!(
                "{page} is served with your own certificate: a secure context if the browser trusts it and it \
                 names {from} (the doctor does not read its names)"
            ),
        )),
    }
    out
}

/// The finding without `--from`: plain HTTP beyond loopback serves pages that get no microphone elsewhere.
fn without_from(http: SocketAddr, https: bool) -> Finding {
    if https {
        Finding::ok(
            "page",
            "the page is served over HTTPS: a secure context wherever its certificate is accepted (--from ADDRESS \
             checks the address a browser will use)",
        )
    } else if http.ip().is_loopback() {
        Finding::ok(
            "page",
            format!(
                "the page at http://localhost:{} is a secure context on this machine (other machines cannot reach \
                 it)",
                http.port()
            ),
        )
    } else {
        Finding::warning(
            "page",
            format!(
                "the page is served over plain HTTP on {http}: opened from another machine it gets no microphone \
                 or camera (browsers give them to HTTPS pages and to http://localhost only)"
            ),
            format!("{HTTPS_FIX}; `doctor --from ADDRESS` checks the address a browser will use"),
        )
    }
}

/// Gathers the facts and makes the findings.
pub fn check(config: &Config, from: Option<&str>) -> Vec<Finding> {
    findings(&gather(config, from))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::Level;

    fn set(list: &[&str]) -> BTreeSet<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    fn facts(http: &str, tls: certificate::Facts, from: Option<&str>) -> Facts {
        Facts {
            http: Some(http.parse().expect("addr")),
            tls,
            from: from.map(host_of),
            allowed_hosts: vec!["robot.local".into()],
            machine: set(&["localhost", "127.0.0.1", "robot.local", "192.168.1.20"]),
        }
    }

    fn self_signed(names: &[&str]) -> certificate::Facts {
        certificate::Facts::SelfSigned {
            cert: "/d/tls/cert.pem".into(),
            parsed: Some(Ok(1)),
            names: set(names),
            wanted: set(&["localhost", "127.0.0.1", "robot.local", "192.168.1.20"]),
        }
    }

    fn problems(f: &[Finding]) -> Vec<&Finding> {
        f.iter().filter(|f| f.level == Level::Problem).collect()
    }

    #[test]
    fn what_a_user_types_for_from_is_reduced_to_its_host() {
        assert_eq!(host_of("robot.local"), "robot.local");
        assert_eq!(host_of("https://Robot.Local:8443/?token=x"), "robot.local");
        assert_eq!(host_of("192.168.1.20:8080"), "192.168.1.20");
        assert_eq!(host_of("[::1]:8080"), "::1");
        assert_eq!(host_of("fe80::1"), "fe80::1");
    }

    #[test]
    fn localhost_and_loopback_addresses_are_secure_over_plain_http() {
        for host in [
            "localhost",
            "app.localhost",
            "127.0.0.1",
            "127.0.1.1",
            "::1",
        ] {
            assert!(is_loopback(host), "{host}");
        }
        for host in ["robot.local", "192.168.1.20", "localhost.example.com"] {
            assert!(!is_loopback(host), "{host}");
        }
        let f = findings(&facts(
            "127.0.0.1:8080",
            certificate::Facts::Off,
            Some("localhost"),
        ));
        assert_eq!(f.len(), 1);
        assert_eq!(f[0].level, Level::Ok, "{}", f[0]);
        assert!(
            f[0].text
                .contains("http://localhost:8080 is a secure context"),
            "{}",
            f[0]
        );
    }

    #[test]
    fn plain_http_from_another_address_is_a_problem_naming_https_as_the_fix() {
        let f = findings(&facts(
            "0.0.0.0:8080",
            certificate::Facts::Off,
            Some("192.168.1.20"),
        ));
        let p = problems(&f);
        assert_eq!(p.len(), 1, "{f:?}");
        assert!(
            p[0].text
                .contains("http://192.168.1.20:8080 is not a secure context"),
            "{}",
            p[0]
        );
        let fix = p[0].fix.as_deref().unwrap_or("");
        assert!(
            fix.contains("--https") && fix.contains("localhost"),
            "{}",
            p[0]
        );
    }

    #[test]
    fn an_address_the_http_server_does_not_listen_on_is_a_problem() {
        let f = findings(&facts(
            "127.0.0.1:8443",
            self_signed(&["localhost", "192.168.1.20"]),
            Some("192.168.1.20"),
        ));
        let p = problems(&f);
        assert_eq!(p.len(), 1, "{f:?}");
        assert!(p[0].text.contains("loopback only"), "{}", p[0]);
        assert!(
            p[0].fix.as_deref().unwrap_or("").contains("0.0.0.0"),
            "{}",
            p[0]
        );
    }

    #[test]
    fn https_with_a_certificate_naming_the_address_is_fine() {
        let f = findings(&facts(
            "0.0.0.0:8443",
            self_signed(&["localhost", "robot.local"]),
            Some("robot.local"),
        ));
        assert!(f.iter().all(|f| f.level == Level::Ok), "{f:?}");
        assert!(
            f[0].text
                .contains("https://robot.local:8443 is a secure context"),
            "{}",
            f[0]
        );
    }

    #[test]
    fn a_certificate_that_does_not_name_the_address_is_a_problem_with_restart_as_the_fix() {
        let f = findings(&facts(
            "0.0.0.0:8443",
            self_signed(&["localhost", "127.0.0.1"]),
            Some("192.168.1.20"),
        ));
        let p = problems(&f);
        assert_eq!(p.len(), 1, "{f:?}");
        assert!(p[0].text.contains("does not name 192.168.1.20"), "{}", p[0]);
        assert!(
            p[0].fix.as_deref().unwrap_or("").contains("restart"),
            "{}",
            p[0]
        );
    }

    #[test]
    fn a_name_outside_allowed_hosts_is_refused_and_the_fix_names_the_key() {
        let f = findings(&facts(
            "0.0.0.0:8443",
            self_signed(&["localhost", "robot.local"]),
            Some("kiosk.lan"),
        ));
        let p = problems(&f);
        assert_eq!(p.len(), 2, "{f:?}");
        assert!(p[0].text.contains("refuses the name kiosk.lan"), "{}", p[0]);
        assert!(
            p[0].fix.as_deref().unwrap_or("").contains("allowed_hosts"),
            "{}",
            p[0]
        );
        assert!(
            p[1].text.contains("one made now would not either"),
            "{}",
            p[1]
        );
    }

    #[test]
    fn a_certificate_not_made_yet_is_judged_by_the_names_it_will_have() {
        let mut tls = self_signed(&[]);
        if let certificate::Facts::SelfSigned { parsed, .. } = &mut tls {
            *parsed = None;
        }
        let f = findings(&facts("0.0.0.0:8443", tls, Some("192.168.1.20")));
        assert!(f.iter().all(|f| f.level == Level::Ok), "{f:?}");
        assert!(f[0].text.contains("will name"), "{}", f[0]);
    }

    #[test]
    fn without_from_plain_http_beyond_loopback_is_a_warning() {
        let f = findings(&facts("0.0.0.0:8080", certificate::Facts::Off, None));
        assert_eq!(f.len(), 1);
        assert_eq!(f[0].level, Level::Warning, "{}", f[0]);
        assert!(f[0].text.contains("no microphone"), "{}", f[0]);
        assert!(
            f[0].fix.as_deref().unwrap_or("").contains("--from"),
            "{}",
            f[0]
        );
        let lan = findings(&facts("192.168.1.20:8080", certificate::Facts::Off, None));
        assert_eq!(lan[0].level, Level::Warning, "{}", lan[0]);
    }

    #[test]
    fn without_from_plain_http_on_loopback_or_https_is_fine() {
        let local = findings(&facts("127.0.0.1:8080", certificate::Facts::Off, None));
        assert_eq!(local[0].level, Level::Ok, "{}", local[0]);
        let https = findings(&facts("0.0.0.0:8443", self_signed(&["localhost"]), None));
        assert_eq!(https[0].level, Level::Ok, "{}", https[0]);
    }
}
