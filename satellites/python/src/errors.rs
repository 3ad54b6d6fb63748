//! The exceptions Python satellites see: one `FlowError` base and a subclass per thing a caller handles
//! differently, mapped from [`flow::FlowError`] and the hub's error codes.

use flow::{ErrorCode, FlowError as RustError};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    _native,
    FlowError,
    PyException,
    "Anything that went wrong talking to the hub."
);
create_exception!(
    _native,
    AuthError,
    FlowError,
    "The hub refused the login token."
);
create_exception!(
    _native,
    TimeoutError,
    FlowError,
    "No answer in time: a service call past its timeout, or a wait that gave up."
);
create_exception!(
    _native,
    ServiceGone,
    FlowError,
    "The service's owner left before it answered."
);
create_exception!(
    _native,
    ServiceFailed,
    FlowError,
    "The service answered with an error (its message is the service's)."
);
create_exception!(
    _native,
    Overloaded,
    FlowError,
    "Too much in flight: the service's queue or a hub limit is full; try again later."
);
create_exception!(
    _native,
    ChannelError,
    FlowError,
    "The channel does not exist, exists already, is of the other kind or belongs to someone else."
);
create_exception!(
    _native,
    DatabaseError,
    FlowError,
    "The pair database refused: no such database, or a storage failure."
);
create_exception!(
    _native,
    ConnectionLost,
    FlowError,
    "The connection is down (it reconnects by itself unless closed), or the client was closed."
);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("FlowError", py.get_type::<FlowError>())?;
    m.add("AuthError", py.get_type::<AuthError>())?;
    m.add("TimeoutError", py.get_type::<TimeoutError>())?;
    m.add("ServiceGone", py.get_type::<ServiceGone>())?;
    m.add("ServiceFailed", py.get_type::<ServiceFailed>())?;
    m.add("Overloaded", py.get_type::<Overloaded>())?;
    m.add("ChannelError", py.get_type::<ChannelError>())?;
    m.add("DatabaseError", py.get_type::<DatabaseError>())?;
    m.add("ConnectionLost", py.get_type::<ConnectionLost>())?;
    Ok(())
}

/// The Python exception for an SDK error, its message kept.
pub fn to_py(e: RustError) -> PyErr {
    let text = e.to_string();
    match &e {
        RustError::Hub(reply) => match reply.code {
            ErrorCode::AuthFailed | ErrorCode::NotAuthenticated | ErrorCode::VersionMismatch => {
                AuthError::new_err(text)
            }
            ErrorCode::Timeout => TimeoutError::new_err(text),
            ErrorCode::ServiceGone => ServiceGone::new_err(text),
            ErrorCode::ServiceFailed => ServiceFailed::new_err(reply.message.clone()),
            ErrorCode::Overloaded | ErrorCode::Limit => Overloaded::new_err(text),
            ErrorCode::NotFound
            | ErrorCode::Exists
            | ErrorCode::NotOwner
            | ErrorCode::WrongKind => ChannelError::new_err(text),
            ErrorCode::Database | ErrorCode::NoDatabase => DatabaseError::new_err(text),
            ErrorCode::ShuttingDown => ConnectionLost::new_err(text),
            ErrorCode::BadRequest | ErrorCode::Internal => FlowError::new_err(text),
        },
        RustError::Timeout(_) => TimeoutError::new_err(text),
        RustError::Connect(_) | RustError::Disconnected(_) | RustError::Closed => {
            ConnectionLost::new_err(text)
        }
        RustError::NotReady(_) => ChannelError::new_err(text),
        RustError::Json(_) => pyo3::exceptions::PyValueError::new_err(text),
        RustError::Protocol(_) | RustError::UnexpectedReply(_) => FlowError::new_err(text),
    }
}

/// Shorthand for results of SDK calls.
pub trait IntoPy<T> {
    fn py_err(self) -> PyResult<T>;
}

impl<T> IntoPy<T> for Result<T, RustError> {
    fn py_err(self) -> PyResult<T> {
        self.map_err(to_py)
    }
}
