//! The application graph of the first SkRobot paper (its Fig. 8), as the hub sees it now: every connection
//! (satellite, module, the page link's module) as a node and every channel as an edge from its owner to its
//! subscribers, with the rates the hub measures. `/api/graph` and the `/graph` page show it. The types only: the
//! hub core fills them (`Hub::graph`), so this file imports nothing of it.

use serde::Serialize;

/// A connection's id, as the hub numbers them (`hub::ConnId`).
type ConnId = u32;

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
