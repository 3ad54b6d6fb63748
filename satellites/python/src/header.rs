//! A channel header as Python gives it, turned into the JSON text the SDK takes. A leaf: both `Client` (creating a
//! channel) and `Publisher` (replacing its header) read headers, so neither imports the other for it.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

/// A channel header: a dict (serialised), a JSON string (checked by the SDK), or nothing (`{}`).
pub fn header_text(header: Option<&Bound<'_, PyAny>>) -> PyResult<String> {
    match header {
        None => Ok("{}".into()),
        Some(h) if h.is_none() => Ok("{}".into()),
        Some(h) => {
            if let Ok(s) = h.cast::<PyString>() {
                return Ok(s.to_str()?.to_owned());
            }
            if h.is_instance_of::<PyDict>() {
                return h
                    .py()
                    .import("json")?
                    .call_method1("dumps", (h,))?
                    .extract();
            }
            Err(PyValueError::new_err(
                "a channel header is a dict or a JSON object as text",
            ))
        }
    }
}
