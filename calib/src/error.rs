//! Errors of the calibration crate.

use std::path::PathBuf;

/// Everything that can go wrong in detection, pose estimation and calibration.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// The AprilTag detector could not be built or run.
    #[error("AprilTag detector: {0}")]
    Detector(String),
    /// No tag of the expected ids was found.
    #[error("no tags found: {0}")]
    NoTags(String),
    /// Too little data to estimate the unknowns.
    #[error("not enough data: {0}")]
    TooFew(String),
    /// The data do not constrain the problem (collinear points, pure rotation, ...).
    #[error("degenerate input: {0}")]
    Degenerate(String),
    /// The optimizer did not reach a usable solution.
    #[error("optimization failed: {0}")]
    Optimization(String),
    /// An invalid option or value.
    #[error("invalid {what}: {message}")]
    Invalid {
        /// Name of the value.
        what: String,
        /// What is wrong.
        message: String,
    },
    /// A file's content is wrong; the message names the field.
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the field or line.
        message: String,
    },
    /// Errors from the core crate (files, camera models, poses).
    #[error(transparent)]
    Core(#[from] tubeloc_core::CoreError),
}

impl CalibError {
    /// Builds [`CalibError::Invalid`].
    pub fn invalid(what: impl Into<String>, message: impl Into<String>) -> Self {
        CalibError::Invalid { what: what.into(), message: message.into() }
    }
    /// Builds [`CalibError::Parse`].
    pub fn parse(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        CalibError::Parse { path: path.into(), message: message.into() }
    }
}
