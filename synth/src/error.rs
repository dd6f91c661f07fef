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
    /// An image could not be encoded or decoded.
    #[error("{path}: {message}")]
    Image {
        /// File concerned.
        path: std::path::PathBuf,
        /// What went wrong.
        message: String,
    },
}
