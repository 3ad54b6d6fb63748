//! The doctor's port check: the configured HTTP address, flow TCP address and Unix socket, each free, answering
//! as a running robot-agent (its `/healthz` answers), or held by something else.

use std::io::{Read, Write};
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use super::finding::Finding;
use crate::config::Config;

/// How long one connection attempt or answer may take.
const PATIENCE: Duration = Duration::from_secs(3);

/// What binding an address found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PortState {
    Free,
    InUse,
    /// The address is none of this machine's: another machine's hub (a satellite's machine checking the robot).
    Elsewhere,
    /// Binding failed for another reason (a privileged port, an address this machine does not have).
    Unusable(String),
}

/// The facts the port findings are made from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Probes {
    /// `[server] http`, its address and state (`None` where it does not parse).
    pub http: (String, Option<(SocketAddr, PortState)>),
    /// `[server] flow_tcp` (`None` when disabled).
    pub flow_tcp: Option<(String, Option<(SocketAddr, PortState)>)>,
    /// The Unix socket's path and state (`None` when disabled).
    pub unix: Option<(PathBuf, PortState)>,
    /// Whether the HTTP address answers `/healthz` as the agent does (over plain HTTP only).
    pub agent_answers: bool,
    /// Whether the page is served over HTTPS (then `/healthz` is not asked).
    pub https: bool,
}

/// The address to connect to for a listening address: loopback in place of "any".
pub fn reachable(addr: SocketAddr) -> SocketAddr {
    match addr.ip() {
        IpAddr::V4(ip) if ip.is_unspecified() => (Ipv4Addr::LOCALHOST, addr.port()).into(),
        IpAddr::V6(ip) if ip.is_unspecified() => (Ipv6Addr::LOCALHOST, addr.port()).into(),
        _ => addr,
    }
}

fn bind_state(addr: SocketAddr) -> PortState {
    match TcpListener::bind(addr) {
        Ok(_) => PortState::Free,
        Err(e) if e.kind() == std::io::ErrorKind::AddrInUse => PortState::InUse,
        Err(e) if e.kind() == std::io::ErrorKind::AddrNotAvailable => PortState::Elsewhere,
        Err(e) => PortState::Unusable(e.to_string()),
    }
}

fn unix_state(path: &Path) -> PortState {
    if std::os::unix::net::UnixStream::connect(path).is_ok() {
        PortState::InUse
    } else {
        // Absent, or a stale file the agent replaces at start.
        PortState::Free
    }
}

/// An answer to [`http_request`], with when the request went out and when the answer began to come back (this
/// machine's clock).
#[derive(Debug, Clone)]
pub struct Reply {
    pub status: u16,
    /// The status line and the header lines.
    pub head: String,
    pub body: String,
    pub sent: SystemTime,
    pub received: SystemTime,
}

impl Reply {
    /// The value of header `name` (any case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.head.lines().skip(1).find_map(|line| {
            let (n, v) = line.split_once(':')?;
            n.trim().eq_ignore_ascii_case(name).then(|| v.trim())
        })
    }
}

/// `GET path` over plain HTTP/1.0 with an optional bearer token, `None` if nothing answers. The connection is made
/// before `sent` is taken, so that the two stamps hold one round trip, not two.
pub fn http_request(addr: SocketAddr, path: &str, token: Option<&str>) -> Option<Reply> {
    let mut stream = TcpStream::connect_timeout(&addr, PATIENCE).ok()?;
    stream.set_read_timeout(Some(PATIENCE)).ok()?;
    stream.set_write_timeout(Some(PATIENCE)).ok()?;
    let auth = token.map_or_else(String::new, |t| format!("Authorization: Bearer {t}\r\n"));
    let request = format!("GET {path} HTTP/1.0\r\nHost: {addr}\r\nConnection: close\r\n{auth}\r\n");
    let sent = SystemTime::now();
    stream.write_all(request.as_bytes()).ok()?;
    let mut raw = vec![0u8; 4096];
    let first = stream.read(&mut raw).ok()?;
    let received = SystemTime::now();
    raw.truncate(first);
    if first > 0 {
        stream.take(4 << 20).read_to_end(&mut raw).ok()?;
    }
    let text = String::from_utf8_lossy(&raw);
    let (head, body) = text.split_once("\r\n\r\n")?;
    let status = head.split_whitespace().nth(1)?.parse().ok()?;
    Some(Reply {
        status,
        head: head.to_string(),
        body: body.to_string(),
        sent,
        received,
    })
}

/// `GET path` as [`http_request`]: the status and body.
pub fn http_get(addr: SocketAddr, path: &str, token: Option<&str>) -> Option<(u16, String)> {
    http_request(addr, path, token).map(|r| (r.status, r.body))
}

/// `HOST:PORT` as an address: an IP address as it is, else the host name looked up (`robot.local:8080`, the hub of
/// a satellite's machine).
pub fn resolve(text: &str) -> Option<SocketAddr> {
    text.parse()
        .ok()
        .or_else(|| text.to_socket_addrs().ok()?.next())
}

/// Binds each configured address to see whether it is free, and asks the HTTP address's `/healthz`.
pub fn probe(config: &Config) -> Probes {
    let http_addr = resolve(&config.server.http);
    let https = config.http.tls_on();
    let http = (
        config.server.http.clone(),
        http_addr.map(|a| (a, bind_state(a))),
    );
    // Asked when something holds the port, and when the address is another machine's (a satellite's machine
    // checking the robot's hub).
    let agent_answers = !https
        && matches!(http.1, Some((_, PortState::InUse | PortState::Elsewhere)))
        && http_addr
            .and_then(|a| http_get(reachable(a), "/healthz", None))
            .is_some_and(|(status, body)| status == 200 && body.trim() == "ok");
    let flow_tcp = (!config.server.flow_tcp.is_empty()).then(|| {
        let addr = config.server.flow_tcp.parse::<SocketAddr>().ok();
        (
            config.server.flow_tcp.clone(),
            addr.map(|a| (a, bind_state(a))),
        )
    });
    let unix = config.unix_socket().map(|p| {
        let state = unix_state(&p);
        (p, state)
    });
    Probes {
        http,
        flow_tcp,
        unix,
        agent_answers,
        https,
    }
}

/// One finding per configured address.
pub fn findings(p: &Probes) -> Vec<Finding> {
    let owner = if p.agent_answers {
        Some("a running robot-agent (its /healthz answers)")
    } else if p.https {
        None
    } else {
        Some("something else (no robot-agent /healthz answers on the HTTP address)")
    };
    let tcp = |what: &str, option: &str, text: &str, probed: &Option<(SocketAddr, PortState)>| {
        match probed {
            None => Finding::problem(
                "ports",
                format!("{what} {text:?} is not an address"),
                format!("set it as HOST:PORT ({option})"),
            ),
            Some((addr, state)) => state_finding(what, &addr.to_string(), option, state, owner),
        }
    };
    let http = match &p.http.1 {
        Some((addr, PortState::Elsewhere)) if p.agent_answers => Finding::ok(
            "ports",
            format!(
                "HTTP {addr} is not this machine's, and a hub answers there (the doctor checks a remote hub)"
            ),
        ),
        probed => tcp("HTTP", "--http or [server] http", &p.http.0, probed),
    };
    let mut out = vec![http];
    if let Some((text, probed)) = &p.flow_tcp {
        out.push(tcp(
            "flow TCP",
            "--flow-tcp or [server] flow_tcp",
            text,
            probed,
        ));
    }
    if let Some((path, state)) = &p.unix {
        out.push(state_finding(
            "flow Unix socket",
            &path.display().to_string(),
            "--flow-unix or [server] flow_unix",
            state,
            owner,
        ));
    }
    out
}

fn state_finding(
    what: &str,
    addr: &str,
    option: &str,
    state: &PortState,
    owner: Option<&str>,
) -> Finding {
    match (state, owner) {
        (PortState::Free, _) => Finding::ok("ports", format!("{what} {addr} is free")),
        (PortState::InUse, Some(o)) if o.starts_with("a running robot-agent") => {
            Finding::ok("ports", format!("{what} {addr} is in use by {o}"))
        }
        (PortState::InUse, Some(o)) => Finding::problem(
            "ports",
            format!("{what} {addr} is in use by {o}"),
            format!("stop that program, or choose another address with {option}"),
        ),
        (PortState::InUse, None) => Finding::warning(
            "ports",
            format!(
                "{what} {addr} is in use (HTTPS is on: the doctor cannot ask /healthz whether it is robot-agent)"
            ),
            format!(
                "if robot-agent is not running, stop the program that holds it or choose another with {option}"
            ),
        ),
        (PortState::Elsewhere, _) => Finding::problem(
            "ports",
            format!("{what} {addr} is not an address of this machine, and no hub answers there"),
            format!("give this machine's address with {option}, or the address of a running hub"),
        ),
        (PortState::Unusable(why), _) => Finding::problem(
            "ports",
            format!("{what} {addr} cannot be bound: {why}"),
            format!("choose an address of this machine and a port above 1023 with {option}"),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::Level;

    fn probes(http: PortState, agent_answers: bool) -> Probes {
        let addr: SocketAddr = "127.0.0.1:8080".parse().expect("addr");
        Probes {
            http: ("127.0.0.1:8080".into(), Some((addr, http))),
            flow_tcp: None,
            unix: Some(("/d/flow.sock".into(), PortState::Free)),
            agent_answers,
            https: false,
        }
    }

    #[test]
    fn free_ports_are_fine() {
        let f = findings(&probes(PortState::Free, false));
        assert!(f.iter().all(|f| f.level == Level::Ok), "{f:?}");
        assert_eq!(f.len(), 2);
    }

    #[test]
    fn a_port_held_by_a_running_agent_is_fine() {
        let f = findings(&probes(PortState::InUse, true));
        assert_eq!(f[0].level, Level::Ok);
        assert!(f[0].text.contains("running robot-agent"), "{}", f[0]);
    }

    #[test]
    fn a_port_held_by_something_else_is_a_problem_with_the_option_to_change_it() {
        let f = findings(&probes(PortState::InUse, false));
        assert_eq!(f[0].level, Level::Problem);
        assert!(f[0].text.contains("something else"), "{}", f[0]);
        assert!(
            f[0].fix.as_deref().unwrap_or("").contains("--http"),
            "{}",
            f[0]
        );
    }

    #[test]
    fn an_address_that_does_not_parse_is_a_problem() {
        let mut p = probes(PortState::Free, false);
        p.flow_tcp = Some(("nowhere".into(), None));
        let f = findings(&p);
        assert!(
            f.iter()
                .any(|f| f.level == Level::Problem && f.text.contains("nowhere"))
        );
    }

    #[test]
    fn another_machines_address_where_a_hub_answers_is_fine() {
        let addr: SocketAddr = "192.0.2.7:8080".parse().expect("addr");
        let mut p = probes(PortState::Free, true);
        p.http = ("192.0.2.7:8080".into(), Some((addr, PortState::Elsewhere)));
        let f = findings(&p);
        assert_eq!(f[0].level, Level::Ok, "{}", f[0]);
        assert!(f[0].text.contains("not this machine's"), "{}", f[0]);
    }

    #[test]
    fn another_machines_address_where_nothing_answers_is_a_problem() {
        let addr: SocketAddr = "192.0.2.7:8080".parse().expect("addr");
        let mut p = probes(PortState::Free, false);
        p.http = ("192.0.2.7:8080".into(), Some((addr, PortState::Elsewhere)));
        assert_eq!(findings(&p)[0].level, Level::Problem);
    }

    #[test]
    fn a_reply_header_is_found_in_any_case() {
        let reply = Reply {
            status: 200,
            head: "HTTP/1.1 200 OK\r\nx-hub-time-us: 42\r\ncontent-length: 2".into(),
            body: "ok".into(),
            sent: SystemTime::UNIX_EPOCH,
            received: SystemTime::UNIX_EPOCH,
        };
        assert_eq!(reply.header("X-Hub-Time-Us"), Some("42"));
        assert_eq!(reply.header("date"), None);
    }

    #[test]
    fn a_bound_listener_is_seen_as_in_use() {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let addr = listener.local_addr().expect("addr");
        assert_eq!(bind_state(addr), PortState::InUse);
        drop(listener);
    }

    #[test]
    fn any_address_is_reached_through_loopback() {
        let any: SocketAddr = "0.0.0.0:8080".parse().expect("addr");
        assert_eq!(reachable(any), "127.0.0.1:8080".parse().expect("addr"));
    }
}
