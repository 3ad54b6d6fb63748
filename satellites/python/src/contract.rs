//! The agent's contract for Python: channel names, kinds and headers from `agent-contract`, and the message types
//! checked by their Rust definitions (serde), so Python reads and writes exactly what Rust producers do.

use agent_contract::channels::{self, Kind};
use agent_contract::{avatar, ctrl, detections, rules, say, transcript};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde::Serialize;
use serde::de::DeserializeOwned;

/// Every fixed channel as `{name: (kind, doc)}`, the fixed headers and the name prefixes.
#[pyfunction]
fn contract_channels(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let out = PyDict::new(py);
    let list = PyDict::new(py);
    for c in channels::ALL {
        let kind = match c.kind {
            Kind::Stream => "stream",
            Kind::Service => "service",
        };
        list.set_item(c.name, (kind, c.doc))?;
    }
    out.set_item("channels", list)?;
    let headers = PyDict::new(py);
    headers.set_item(channels::AUDIO.name, channels::headers::AUDIO)?;
    headers.set_item(channels::VIDEO.name, channels::headers::VIDEO)?;
    headers.set_item(channels::CTRL.name, channels::headers::CTRL)?;
    headers.set_item(channels::VIDEO_Y.name, channels::headers::VIDEO_Y)?;
    headers.set_item(channels::AVATAR.name, channels::headers::AVATAR)?;
    headers.set_item(channels::SAY.name, channels::headers::SAY)?;
    headers.set_item(channels::RULES.name, channels::headers::RULES)?;
    headers.set_item(channels::TRANSCRIPT.name, channels::headers::TRANSCRIPT)?;
    headers.set_item(channels::CHAT.name, channels::headers::CHAT)?;
    headers.set_item(channels::CHAT_REPLY.name, channels::headers::CHAT_REPLY)?;
    out.set_item("headers", headers)?;
    out.set_item("asr_claim_prefix", channels::ASR_CLAIM_PREFIX)?;
    out.set_item("asr_presence_prefix", channels::ASR_PRESENCE_PREFIX)?;
    Ok(out)
}

fn canonical<T: Serialize + DeserializeOwned>(kind: &str, data: &[u8]) -> PyResult<String> {
    let value: T = serde_json::from_slice(data)
        .map_err(|e| PyValueError::new_err(format!("not a valid {kind} message: {e}")))?;
    serde_json::to_string(&value).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// Checks `data` against the contract type `kind` and returns it as the Rust side writes it (JSON text): unknown
/// shapes fail here with serde's reason, missing optional fields appear with their defaults.
#[pyfunction]
fn contract_check(kind: &str, data: &[u8]) -> PyResult<String> {
    match kind {
        "detections" => canonical::<detections::DetectionsMsg>(kind, data),
        "faces" => canonical::<detections::FacesMsg>(kind, data),
        "motion" => canonical::<detections::MotionMsg>(kind, data),
        "codes" => canonical::<detections::CodesMsg>(kind, data),
        "gaze" => canonical::<detections::GazeCommand>(kind, data),
        "transcript" => canonical::<transcript::TranscriptMessage>(kind, data),
        "vad" => canonical::<transcript::VadMessage>(kind, data),
        "heard" => canonical::<transcript::Heard>(kind, data),
        "avatar" => canonical::<avatar::AvatarCommand>(kind, data),
        "say_request" => canonical::<say::SayRequest>(kind, data),
        "say_answer" => canonical::<say::SayAnswer>(kind, data),
        "ctrl" => canonical::<ctrl::Ctrl>(kind, data),
        "rule_change" => canonical::<rules::RuleChange>(kind, data),
        other => Err(PyValueError::new_err(format!(
            "no contract type {other:?}; known: detections, faces, motion, codes, gaze, transcript, vad, heard, \
             avatar, say_request, say_answer, ctrl, rule_change"
        ))),
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(contract_channels, m)?)?;
    m.add_function(wrap_pyfunction!(contract_check, m)?)?;
    Ok(())
}
