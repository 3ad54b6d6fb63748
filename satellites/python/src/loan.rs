//! `Loan`: a message written in place into a slot of its channel's shared-memory segment (`Publisher.loan(size)`),
//! exposed as a writable buffer (`memoryview(loan)`, `numpy.frombuffer(loan, dtype=...)`), so that a producer
//! decodes or renders a frame straight into the memory its subscribers read, and the SDK copies nothing.
//!
//! The slot belongs to the writer only until it is published: then the hub and the subscribers read it. So a loan
//! counts the views it has handed out, and `publish()` and `discard()` refuse (`BufferError`) while one is still
//! alive, as `bytearray` refuses to resize under a view. A view is released with `del`, `view.release()` or a
//! `with memoryview(loan) as view:` block.
//!
//! The binding's second `unsafe` block lives here: handing CPython a writable pointer into the slot.

use std::os::raw::c_int;

use pyo3::exceptions::{PyBufferError, PyValueError};
use pyo3::ffi;
use pyo3::prelude::*;

use crate::errors::{ChannelError, IntoPy};

/// A message being written in place; published with `publish()`, given back with `discard()` (or when dropped).
#[pyclass(module = "flow._native")]
#[derive(Debug)]
pub struct Loan {
    channel: String,
    /// `None` once published or discarded.
    loan: Option<flow::Loan>,
    /// Buffer views handed out and not yet released.
    views: usize,
}

impl Loan {
    pub fn new(channel: String, loan: flow::Loan) -> Self {
        Loan {
            channel,
            loan: Some(loan),
            views: 0,
        }
    }

    /// The loan, unless a view over it is still alive or it is spent.
    fn take(&mut self, what: &str) -> PyResult<flow::Loan> {
        if self.views > 0 {
            return Err(PyBufferError::new_err(format!(
                "{}: cannot {what} the loan while {} view(s) of it are alive (del them, call view.release(), \
                 or write inside `with memoryview(loan) as view:`)",
                self.channel, self.views
            )));
        }
        self.loan.take().ok_or_else(|| {
            ChannelError::new_err(format!(
                "{}: the loan was already published or discarded",
                self.channel
            ))
        })
    }
}

#[pymethods]
impl Loan {
    /// The channel the message will be published on.
    #[getter]
    fn channel(&self) -> &str {
        &self.channel
    }

    /// Whether the loan is still to be published (neither published nor discarded).
    #[getter]
    fn pending(&self) -> bool {
        self.loan.is_some()
    }

    /// The message's size in bytes (0 once spent).
    fn __len__(&self) -> usize {
        self.loan.as_ref().map_or(0, flow::Loan::len)
    }

    /// Publishes the message (its first `length` bytes, if given), waiting with the GIL released only while the
    /// connection's send queue is full. The loan is spent.
    #[pyo3(signature = (length=None))]
    fn publish(&mut self, py: Python<'_>, length: Option<usize>) -> PyResult<()> {
        if let Some(n) = length
            && n > self.__len__()
        {
            return Err(PyValueError::new_err(format!(
                "{}: length {n} is longer than the loan's {} bytes",
                self.channel,
                self.__len__()
            )));
        }
        let mut loan = self.take("publish")?;
        if let Some(n) = length {
            loan.truncate(n);
        }
        crate::runtime::wait(py, loan.publish())?.py_err()
    }

    /// Gives the slot back unpublished.
    fn discard(&mut self) -> PyResult<()> {
        self.take("discard").map(drop)
    }

    fn __repr__(&self) -> String {
        match &self.loan {
            Some(loan) => format!("Loan(channel={:?}, {} bytes)", self.channel, loan.len()),
            None => format!("Loan(channel={:?}, spent)", self.channel),
        }
    }

    /// A writable buffer over the slot; the loan stays alive, and cannot be published, while a view exists.
    #[allow(unsafe_code)]
    unsafe fn __getbuffer__(
        slf: Bound<'_, Self>,
        view: *mut ffi::Py_buffer,
        flags: c_int,
    ) -> PyResult<()> {
        let py = slf.py();
        let mut this = slf.try_borrow_mut()?;
        let channel = this.channel.clone();
        let data = this
            .loan
            .as_mut()
            .ok_or_else(|| {
                PyBufferError::new_err(format!("{channel}: the loan was published or discarded"))
            })?
            .as_mut_slice();
        let len = ffi::Py_ssize_t::try_from(data.len())
            .map_err(|_| PyBufferError::new_err("loan too large"))?;
        let ptr = data.as_mut_ptr();
        // SAFETY: `view` is the buffer CPython asks us to fill. The pointer is into the slot this loan holds: the
        // mapping it lies in is kept by the loan, which stays in this object until `publish()` or `discard()`
        // takes it, and both refuse while `views` (counted below, released in `__releasebuffer__`) is above zero.
        // `PyBuffer_FillInfo` takes a reference to the object (`view.obj`), which CPython drops only after the view
        // is released, so the object, and the slot with it, outlives every view.
        let rc = unsafe { ffi::PyBuffer_FillInfo(view, slf.as_ptr(), ptr.cast(), len, 0, flags) };
        if rc == 0 {
            this.views += 1;
            Ok(())
        } else {
            Err(PyErr::fetch(py))
        }
    }

    #[allow(unsafe_code)]
    unsafe fn __releasebuffer__(&mut self, _view: *mut ffi::Py_buffer) {
        self.views = self.views.saturating_sub(1);
    }
}
