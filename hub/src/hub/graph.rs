//! The application graph of the first SkRobot paper (its Fig. 8), as the hub sees it now: every connection
//! (satellite, module, the page link's module) as a node and every channel as an edge from its owner to its
//! subscribers, with the rates the hub measures. `/api/graph` and the `/graph` page show it.

use serde::Serialize;

use super::{ConnId, State};

/// A connection: a satellite, a tool or a module.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GraphNode {
    pub id: ConnId,
    /// The login name (the part of the label before `#`).
    pub name: String,
    /// `name#id`, as channel owners are shown.
    pub label: String,
    /// `tcp`, `unix`, `ws` or `module`.
    pub transport: String,
}

/// A channel from its owner to its subscribers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GraphChannel {
    pub name: String,
    pub kind: &'static str,
    pub from: ConnId,
    pub to: Vec<ConnId>,
    pub msgs_per_s: f32,
    pub bytes_per_s: f32,
    /// Messages dropped for subscribers that fell behind, since the channel was created.
    pub dropped: u64,
}

/// The whole graph at one moment.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Graph {
    pub nodes: Vec<GraphNode>,
    pub channels: Vec<GraphChannel>,
}

pub(super) fn snapshot(st: &State) -> Graph {
    let mut nodes: Vec<GraphNode> = st
        .conns
        .iter()
        .map(|(&id, c)| GraphNode {
            id,
            name: c
                .label
                .rsplit_once('#')
                .map_or(c.label.as_str(), |(n, _)| n)
                .to_string(),
            label: c.label.clone(),
            transport: c.transport.clone(),
        })
        .collect();
    nodes.sort_by_key(|n| n.id);
    let mut channels: Vec<GraphChannel> = st
        .channels
        .values()
        .map(|ch| {
            let mut to: Vec<ConnId> = ch.subscribers.iter().map(|(c, _)| *c).collect();
            to.sort_unstable();
            GraphChannel {
                name: ch.name.clone(),
                kind: ch.kind.as_str(),
                from: ch.owner,
                to,
                msgs_per_s: ch.rate.msgs_per_s,
                bytes_per_s: ch.rate.bytes_per_s,
                dropped: ch.dropped,
            }
        })
        .collect();
    channels.sort_by(|a, b| a.name.cmp(&b.name));
    Graph { nodes, channels }
}
