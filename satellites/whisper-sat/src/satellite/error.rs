//! What stops a satellite: the hub, the segmentation thread, or the decode task failing.

use crate::stream::StreamError;
use flow::FlowError;
use tokio::sync::{broadcast, watch};

/// Why a satellite (or one of its tasks) stopped.
#[derive(Debug, thiserror::Error)]
pub enum SatelliteError {
    /// The presence channel is named after the satellite, so a second one of the same name cannot create it.
    #[error("creating the presence channel (is another satellite running with this --name?)")]
    Presence(#[source] FlowError),
    /// A hub request (subscribing, listing channels, taking a role) failed.
    #[error(transparent)]
    Hub(#[from] FlowError),
    /// The segmenter's configuration was refused.
    #[error(transparent)]
    Stream(#[from] StreamError),
    /// The segmentation thread could not be started.
    #[error(transparent)]
    Thread(#[from] std::io::Error),
    /// The blocking task running a decode panicked: the transcriber is lost with it.
    #[error("the transcription task panicked")]
    DecodePanicked,
    /// The switch that follows `Agent.ctrl` went away.
    #[error(transparent)]
    Switch(#[from] watch::error::RecvError),
    /// The client's event stream closed.
    #[error(transparent)]
    Events(#[from] broadcast::error::RecvError),
}
