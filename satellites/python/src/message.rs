//! `Message`: one message as Python sees it, its payload shared with the Rust SDK's buffer and exposed through the
//! buffer protocol, so `memoryview(msg)`, `msg.data` and `msg.pcm()` read it where it lies.
//!
//! One of the binding's two `unsafe` blocks lives here (the other is `loan.rs`): handing CPython a pointer into the
//! payload.

use std::os::raw::c_int;

use bytes::Bytes;
use pyo3::ffi;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

/// One message: from a subscription (with its place on the channel) or a service's answer.
#[pyclass(frozen, module = "flow._native")]
#[derive(Debug)]
pub struct Message {
    channel: String,
    seq: u64,
    ts_us: u64,
    /// Messages lost on the way to this one (hub or local queue dropped the oldest), from the gap in `seq`.
    gap: u64,
    payload: Bytes,
}

impl Message {
    pub fn new(channel: String, seq: u64, ts_us: u64, gap: u64, payload: Bytes) -> Self {
        Message {
            channel,
            seq,
            ts_us,
            gap,
            payload,
        }
    }

    pub fn payload(&self) -> &Bytes {
        &self.payload
    }
}

#[pymethods]
impl Message {
    /// The channel's name.
    #[getter]
    fn channel(&self) -> &str {
        &self.channel
    }

    /// Position on the channel, from 1 (0 for a service answer).
    #[getter]
    fn seq(&self) -> u64 {
        self.seq
    }

    /// Hub clock when the message was published, in microseconds since the Unix epoch.
    #[getter]
    fn ts_us(&self) -> u64 {
        self.ts_us
    }

    /// How many messages of this channel were dropped just before this one (drop-oldest on a slow reader).
    #[getter]
    fn gap(&self) -> u64 {
        self.gap
    }

    /// Whether the payload lies in a shared-memory segment this process maps: it came by reference over the hub's
    /// Unix socket, and every view of it (`memoryview`, numpy) reads the segment itself, without a copy.
    #[getter]
    fn in_shared_memory(&self) -> bool {
        flow::shm::is_shared(&self.payload)
    }

    /// The payload as a read-only `memoryview`, without a copy.
    #[getter]
    fn data<'py>(slf: Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let py = slf.py();
        py.import("builtins")?.getattr("memoryview")?.call1((slf,))
    }

    /// The payload copied into `bytes`.
    fn bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.payload)
    }

    /// The payload decoded as UTF-8.
    fn text(&self) -> PyResult<String> {
        std::str::from_utf8(&self.payload)
            .map(str::to_owned)
            .map_err(|e| {
                pyo3::exceptions::PyValueError::new_err(format!(
                    "{}: the payload is not UTF-8 text: {e}",
                    self.channel
                ))
            })
    }

    /// The payload parsed as JSON (`ValueError` naming the channel if it is not).
    fn json<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let text = self.text()?;
        py.import("json")?
            .call_method1("loads", (text,))
            .map_err(|e| {
                pyo3::exceptions::PyValueError::new_err(format!(
                    "{}: the payload is not JSON: {e}",
                    self.channel
                ))
            })
    }

    /// The payload as a numpy `int16` array (s16le PCM), a view on the message without a copy.
    fn pcm<'py>(slf: Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let py = slf.py();
        let numpy = py.import("numpy").map_err(|_| {
            pyo3::exceptions::PyImportError::new_err("Message.pcm() needs numpy: pip install numpy")
        })?;
        if !slf.get().payload.len().is_multiple_of(2) {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "{}: {} bytes is not whole s16 samples",
                slf.get().channel,
                slf.get().payload.len()
            )));
        }
        numpy.call_method1("frombuffer", (slf, "<i2"))
    }

    fn __len__(&self) -> usize {
        self.payload.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "Message(channel={:?}, seq={}, ts_us={}, {} bytes)",
            self.channel,
            self.seq,
            self.ts_us,
            self.payload.len()
        )
    }

    /// Read-only buffer over the payload; the message stays alive while a view exists.
    #[allow(unsafe_code)]
    unsafe fn __getbuffer__(
        slf: Bound<'_, Self>,
        view: *mut ffi::Py_buffer,
        flags: c_int,
    ) -> PyResult<()> {
        let py = slf.py();
        let data = &slf.get().payload;
        let len = ffi::Py_ssize_t::try_from(data.len())
            .map_err(|_| pyo3::exceptions::PyBufferError::new_err("payload too large"))?;
        // SAFETY: `view` is the buffer CPython asks us to fill. The pointer is into `payload`, a `Bytes` that never
        // moves or changes while this frozen object lives, and `PyBuffer_FillInfo` takes a reference to the object
        // (`view.obj`), which CPython releases only after the last view is gone. The view is marked read-only, and
        // a request for a writable view fails inside `PyBuffer_FillInfo` with `BufferError`.
        let rc = unsafe {
            ffi::PyBuffer_FillInfo(
                view,
                slf.as_ptr(),
                data.as_ptr() as *mut std::ffi::c_void,
                len,
                1,
                flags,
            )
        };
        if rc == 0 {
            Ok(())
        } else {
            Err(PyErr::fetch(py))
        }
    }
}
