//! The library's typed errors as Python exceptions. The message is the error's own text (it
//! names the value and its allowed range, or the file and the failed check); only the class is
//! chosen here:
//!
//! - `FileNotFoundError` / `PermissionError` / `OSError`: the operating system refused a read or
//!   write (an `std::io::Error` anywhere in the error's chain);
//! - `RuntimeError`: the input was valid but the work could not finish (an adaptive quadrature
//!   that did not converge, a bake directory locked by another process);
//! - `ValueError`: everything else, an input outside its range or a file that fails its contract.

use std::error::Error;
use std::io::ErrorKind;

use pyo3::PyErr;
use pyo3::exceptions::{
    PyFileNotFoundError, PyOSError, PyPermissionError, PyRuntimeError, PyValueError,
};

/// The Python exception for `e`, with `e`'s message (its whole chain is in it already: every
/// library error's text includes its cause).
pub fn to_py(e: &(dyn Error + 'static)) -> PyErr {
    let message = e.to_string();
    let mut cause: Option<&(dyn Error + 'static)> = Some(e);
    while let Some(c) = cause {
        if let Some(io) = c.downcast_ref::<std::io::Error>() {
            return match io.kind() {
                ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
                ErrorKind::PermissionDenied => PyPermissionError::new_err(message),
                _ => PyOSError::new_err(message),
            };
        }
        if matches!(
            c.downcast_ref::<mie::MieError>(),
            Some(mie::MieError::NotConverged { .. })
        ) || matches!(
            c.downcast_ref::<format::CommitError>(),
            Some(format::CommitError::Locked { .. })
        ) || matches!(
            // `BakeError::Commit` is transparent: its `source()` skips the `CommitError`.
            c.downcast_ref::<bake::BakeError>(),
            Some(bake::BakeError::Commit(format::CommitError::Locked { .. }))
        ) {
            return PyRuntimeError::new_err(message);
        }
        cause = c.source();
    }
    PyValueError::new_err(message)
}

/// `ValueError` naming `name`, its `value` and the allowed `range`, worded as the library's
/// own range errors are.
pub fn out_of_range(name: &str, value: impl std::fmt::Display, range: &str) -> PyErr {
    PyValueError::new_err(format!(
        "{name} = {value} is outside the allowed range {range}"
    ))
}
