//! The pipeline's error type.

use thiserror::Error;

/// What can go wrong in a [`crate::Locator`] run. Messages name the input (image, detection
/// index, camera) at fault.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum PipelineError {
    /// An input is unusable: wrong image size, unknown camera, a detection whose mask is not the
    /// image's size, a missing stereo pair.
    #[error("{0}")]
    Input(String),
    /// The detector failed.
    #[error("detection: {0}")]
    Detect(String),
    /// Stereo rectification or matching failed.
    #[error("stereo: {0}")]
    Stereo(#[from] tubeloc_stereo::StereoError),
    /// The refiner could not be built (tube model, configuration).
    #[error(transparent)]
    Refine(#[from] tubeloc_refine::RefineError),
    /// An error from the core types.
    #[error(transparent)]
    Core(#[from] tubeloc_core::CoreError),
}

/// Result with a [`PipelineError`].
pub type Result<T, E = PipelineError> = std::result::Result<T, E>;
