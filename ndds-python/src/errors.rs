//! The exceptions `ndds` raises, and the SDK's errors mapped onto them.

use ndds_client::ports::PortError;
use ndds_client::{ConnectError, DeclareError, QueryError, RecvError, WriteError};
use pyo3::PyErr;
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyTypeError, PyValueError};

create_exception!(
    ndds,
    Error,
    PyException,
    "Base class of the errors ndds raises (besides TypeError and ValueError for bad samples)."
);
create_exception!(
    ndds,
    Timeout,
    Error,
    "An operation did not finish within its timeout. Its message says what was waited for and, \
     where known, why nothing came (for example a producer of another type on the topic)."
);
create_exception!(
    ndds,
    Refused,
    Error,
    "A port's owner refused this user: the message names the port, the owner, the user and the \
     restriction."
);
create_exception!(
    ndds,
    Disconnected,
    Error,
    "The daemon is gone (and did not come back), or the endpoint was closed."
);
create_exception!(
    ndds,
    IncompatibleType,
    Error,
    "The other side of a port uses other message types; the message names both."
);

pub(crate) fn connect_error(err: ConnectError) -> PyErr {
    Disconnected::new_err(format!("cannot connect: {err}"))
}

pub(crate) fn declare_error(err: DeclareError) -> PyErr {
    match err {
        DeclareError::Disconnected => {
            Disconnected::new_err("the daemon is gone: the endpoint cannot be declared")
        }
        DeclareError::Timeout(what) => Timeout::new_err(what),
        other => Error::new_err(other.to_string()),
    }
}

pub(crate) fn write_error(err: WriteError) -> PyErr {
    match err {
        WriteError::TooLarge { .. } => PyValueError::new_err(err.to_string()),
        WriteError::WouldBlock { .. } => Timeout::new_err(err.to_string()),
        WriteError::Serialize(_) => PyTypeError::new_err(err.to_string()),
        other => Error::new_err(other.to_string()),
    }
}

pub(crate) fn recv_error(err: RecvError) -> PyErr {
    match err {
        RecvError::Timeout | RecvError::TimeoutUnmatched(_) => Timeout::new_err(err.to_string()),
        RecvError::Closed => Disconnected::new_err("the consumer is closed"),
        other => Error::new_err(other.to_string()),
    }
}

pub(crate) fn query_error(err: QueryError) -> PyErr {
    match err {
        QueryError::Disconnected => Disconnected::new_err(err.to_string()),
        QueryError::Timeout => Timeout::new_err(err.to_string()),
    }
}

pub(crate) fn port_error(err: PortError) -> PyErr {
    match err {
        PortError::Timeout { .. } | PortError::WaitFor { .. } => Timeout::new_err(err.to_string()),
        PortError::Refused { .. } => Refused::new_err(err.to_string()),
        PortError::Format { .. } => IncompatibleType::new_err(err.to_string()),
        other => Error::new_err(other.to_string()),
    }
}

pub(crate) fn closed() -> PyErr {
    Disconnected::new_err("the endpoint is closed")
}
