//! Errors of the refine crate (invalid configuration or model; fit failures are not errors but
//! flagged results, see [`tubeloc_core::TubeAxisPose::failure`]).

/// An error building a refiner or a seed.
#[derive(Debug, thiserror::Error)]
pub enum RefineError {
    /// The tube model cannot be used (no sections, non-positive sizes).
    #[error("invalid tube model: {0}")]
    Model(String),
    /// A setting is out of range: the message names the field (`group.field`), its value and
    /// the allowed range.
    #[error("refine config: {0}")]
    Config(String),
    /// The detection carries no usable seed.
    #[error("unusable seed: {0}")]
    Seed(String),
    /// An error from the core types.
    #[error(transparent)]
    Core(#[from] tubeloc_core::CoreError),
}
