//! `tubeloc.TubelocError`: every error of the library, with the message the CLI prints.

use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::PyErr;

create_exception!(tubeloc, TubelocError, PyValueError, "An error of tubeloc (bad input, a file that cannot be read, a failed pipeline step); the message is the one `tubeloc` prints.");

/// The error as a `TubelocError` carrying its message.
pub fn to_py(e: impl std::fmt::Display) -> PyErr {
    TubelocError::new_err(e.to_string())
}

/// The error with its sources, as the CLI prints it (`{:#}`: each source after ": ").
pub fn chain_to_py(e: &(dyn std::error::Error + 'static)) -> PyErr {
    TubelocError::new_err(tubeloc_pipeline::shipped::error_chain(e))
}

/// `context: ` and the error with its sources (the CLI's `with_context`).
pub fn context_to_py(context: impl std::fmt::Display, e: &(dyn std::error::Error + 'static)) -> PyErr {
    TubelocError::new_err(format!("{context}: {}", tubeloc_pipeline::shipped::error_chain(e)))
}
