//! The doctor's look at a running agent: which satellites are connected (`/api/graph`, with the user token from
//! the data directory), and whether the ones the default set-up runs, a speech satellite and the language model,
//! are among them.

use flow::token::{TokenKind, resolve_token};

use super::finding::Finding;
use super::ports::{Probes, http_get, reachable};
use crate::config::Config;

/// A connection the hub lists: its login name and transport (`module` for the agent's own parts).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Node {
    pub name: String,
    pub transport: String,
}

/// What asking the agent gave: `None` when no agent answers, the connections, or why they could not be listed.
pub type Facts = Option<Result<Vec<Node>, String>>;

/// Asks the running agent for its connections.
pub fn gather(config: &Config, probes: &Probes) -> Facts {
    if !probes.agent_answers {
        return None;
    }
    let addr = reachable(probes.http.1.as_ref()?.0);
    let token = match resolve_token(None, &config.server.data_dir, TokenKind::User) {
        Ok(t) => t,
        Err(e) => return Some(Err(e.to_string())),
    };
    let Some((status, body)) = http_get(addr, "/api/graph", Some(&token)) else {
        return Some(Err("GET /api/graph got no answer".into()));
    };
    if status != 200 {
        return Some(Err(format!("GET /api/graph answered {status}")));
    }
    let graph: serde_json::Value = match serde_json::from_str(&body) {
        Ok(v) => v,
        Err(e) => return Some(Err(format!("GET /api/graph: {e}"))),
    };
    let nodes = graph
        .get("nodes")
        .and_then(serde_json::Value::as_array)
        .map(|nodes| {
            nodes
                .iter()
                .map(|n| Node {
                    name: n.get("name").and_then(|v| v.as_str()).unwrap_or("").into(),
                    transport: n
                        .get("transport")
                        .and_then(|v| v.as_str())
                        .unwrap_or("")
                        .into(),
                })
                .collect()
        })
        .unwrap_or_default();
    Some(Ok(nodes))
}

/// The findings about the satellites.
pub fn findings(facts: &Facts) -> Vec<Finding> {
    match facts {
        None => vec![Finding::ok(
            "agent",
            "no robot-agent answers on the HTTP address (or it speaks HTTPS): satellites not checked",
        )],
        Some(Err(why)) => vec![Finding::warning(
            "agent",
            format!("the running agent's connections could not be listed: {why}"),
            "run the doctor as the agent's user, with the same --data-dir (it reads the token there)",
        )],
        Some(Ok(nodes)) => {
            let satellites: Vec<&Node> = nodes.iter().filter(|n| n.transport != "module").collect();
            let has = |prefix: &str| satellites.iter().any(|n| n.name.starts_with(prefix));
            let listed: Vec<String> = satellites
                .iter()
                .map(|n| format!("{} ({})", n.name, n.transport))
                .collect();
            let mut out = vec![Finding::ok(
                "agent",
                if listed.is_empty() {
                    "robot-agent runs with no satellite connected".to_string()
                } else {
                    format!(
                        "robot-agent runs; connected: {} (the hub does not show which model each uses)",
                        listed.join(", ")
                    )
                },
            )];
            if !has("whisper-") {
                out.push(Finding::warning(
                    "agent",
                    "no speech satellite (whisper-*) is connected: the agent hears nothing",
                    "start whisper-sat (`make run` starts one; installed: systemctl start whisper-sat@1)",
                ));
            }
            if !has("llm-") {
                out.push(Finding::warning(
                    "agent",
                    "no language-model satellite (llm-*) is connected: chat(T) turns get no answer",
                    "start llm-sat (installed: systemctl start llm-sat)",
                ));
            }
            out
        }
    }
}

/// Asks the agent and makes the findings.
pub fn check(config: &Config, probes: &Probes) -> Vec<Finding> {
    findings(&gather(config, probes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::Level;

    fn node(name: &str, transport: &str) -> Node {
        Node {
            name: name.into(),
            transport: transport.into(),
        }
    }

    #[test]
    fn connected_satellites_are_listed_without_the_modules() {
        let f = findings(&Some(Ok(vec![
            node("whisper-robot-1", "unix"),
            node("llm-42", "unix"),
            node("tts", "module"),
        ])));
        assert_eq!(f.len(), 1, "{f:?}");
        assert!(f[0].text.contains("whisper-robot-1 (unix)"), "{}", f[0]);
        assert!(!f[0].text.contains("tts"), "{}", f[0]);
    }

    #[test]
    fn a_missing_speech_satellite_is_a_warning_with_how_to_start_it() {
        let f = findings(&Some(Ok(vec![node("llm-42", "tcp")])));
        let w = f
            .iter()
            .find(|f| f.level == Level::Warning)
            .expect("a warning");
        assert!(w.text.contains("whisper"), "{w}");
        assert!(
            w.fix.as_deref().unwrap_or("").contains("whisper-sat"),
            "{w}"
        );
    }

    #[test]
    fn an_agent_that_is_not_running_is_not_a_problem() {
        let f = findings(&None);
        assert_eq!(f.len(), 1);
        assert_eq!(f[0].level, Level::Ok);
    }
}
