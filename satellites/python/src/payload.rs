//! What Python may publish or send: `bytes` (shared, not copied), `str` (UTF-8), a `dict` or `list` (JSON), or any
//! object with a C-contiguous buffer (`bytearray`, `memoryview`, a numpy array), read from its buffer.

use bytes::Bytes;
use pyo3::buffer::PyBuffer;
use pyo3::prelude::*;
use pyo3::pybacked::PyBackedBytes;
use pyo3::types::{PyBytes, PyDict, PyList, PyString};

use crate::message::Message;

/// The payload bytes of `obj`.
pub fn to_bytes(obj: &Bound<'_, PyAny>) -> PyResult<Bytes> {
    if let Ok(b) = obj.cast::<PyBytes>() {
        // Keeps a reference to the Python object instead of copying its bytes.
        let backed: PyBackedBytes = b.clone().into();
        return Ok(Bytes::from_owner(backed));
    }
    if let Ok(s) = obj.cast::<PyString>() {
        return Ok(Bytes::from(s.to_str()?.to_owned()));
    }
    if obj.is_instance_of::<PyDict>() || obj.is_instance_of::<PyList>() {
        let text: String = obj
            .py()
            .import("json")?
            .call_method1("dumps", (obj,))?
            .extract()?;
        return Ok(Bytes::from(text));
    }
    if let Ok(msg) = obj.cast::<Message>() {
        return Ok(msg.get().payload().clone());
    }
    // Anything else through the buffer protocol, as bytes whatever its item type (an int16 array is its s16le
    // samples): a byte view of it is taken in Python, and one copy into the frame is made here.
    let py = obj.py();
    let bytes_view = py
        .import("builtins")?
        .getattr("memoryview")?
        .call1((obj,))
        .and_then(|view| view.call_method1("cast", ("B",)))
        .map_err(|_| {
            pyo3::exceptions::PyTypeError::new_err(format!(
                "cannot publish a {}: give bytes, str, a dict or list (sent as JSON), or a contiguous buffer \
                 such as a numpy array",
                obj.get_type().name().map_or_else(|_| "?".into(), |n| n.to_string())
            ))
        })?;
    let buffer = PyBuffer::<u8>::get(&bytes_view)?;
    Ok(Bytes::from(buffer.to_vec(py)?))
}
