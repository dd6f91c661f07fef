//! Errors of the synth crate.

/// An error while generating, rendering or writing synthetic data.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// A parameter is out of range or inconsistent.
    #[error("invalid synth parameter: {0}")]
    Invalid(String),
    /// A core operation (file, camera, pose) failed.
    #[error(transparent)]
    Core(#[from] tubeloc_core::CoreError),
    /// A data file (a real data folder's manifest or camera list) is missing or malformed.
    #[error("{path}: {message}")]
    Data {
        /// File concerned.
        path: std::path::PathBuf,
        /// What went wrong.
        message: String,
    },
    /// An image could not be encoded or decoded.
    #[error("{path}: {message}")]
    Image {
        /// File concerned.
        path: std::path::PathBuf,
        /// What went wrong.
        message: String,
    },
}
