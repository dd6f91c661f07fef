//! Errors of the core crate. Every error that comes from a file names the file.

use std::path::PathBuf;

/// An error raised while reading, validating or writing core types.
#[derive(Debug, thiserror::Error)]
pub enum CoreError {
    /// The file could not be read or written.
    #[error("{path}: {error}")]
    Io {
        /// File concerned.
        path: PathBuf,
        /// Underlying I/O error (part of the message, so not also a `source()` that error
        /// chains would print a second time).
        error: std::io::Error,
    },
    /// The file was read but its content is not valid.
    #[error("{path}: {message}")]
    Parse {
        /// File concerned.
        path: PathBuf,
        /// What is wrong, naming the field or line.
        message: String,
    },
    /// A value is out of its valid range (not tied to a file).
    #[error("invalid {what}: {message}")]
    Invalid {
        /// Name of the value or field.
        what: String,
        /// What is wrong with it.
        message: String,
    },
}

impl CoreError {
    /// Builds a [`CoreError::Parse`] for `path`.
    pub fn parse(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        CoreError::Parse { path: path.into(), message: message.into() }
    }
    /// Builds a [`CoreError::Invalid`].
    pub fn invalid(what: impl Into<String>, message: impl Into<String>) -> Self {
        CoreError::Invalid { what: what.into(), message: message.into() }
    }
    /// Builds a [`CoreError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        CoreError::Io { path: path.into(), error: source }
    }
}
