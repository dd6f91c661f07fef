//! Errors of the stereo crate.

use tubeloc_core::CoreError;

/// An error raised by rectification, matching or triangulation.
#[derive(Debug, thiserror::Error)]
pub enum StereoError {
    /// The two images (or an image and its camera) do not have the same size.
    #[error("image size mismatch: {what} is {a_w}x{a_h} but {other} is {b_w}x{b_h}")]
    SizeMismatch {
        /// First item compared.
        what: String,
        /// Width of the first item.
        a_w: usize,
        /// Height of the first item.
        a_h: usize,
        /// Second item compared.
        other: String,
        /// Width of the second item.
        b_w: usize,
        /// Height of the second item.
        b_h: usize,
    },
    /// The camera pair cannot be rectified (zero baseline, baseline along the optical axis...).
    #[error("unrectifiable stereo pair: {0}")]
    Unrectifiable(String),
    /// A parameter is out of range.
    #[error("invalid stereo parameter {name}: {message}")]
    InvalidParam {
        /// Parameter name.
        name: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A region of interest is empty or lies outside the image.
    #[error("invalid region of interest {roi:?}: {message}")]
    InvalidRegion {
        /// The region as `(x, y, w, h)` pixels.
        roi: (i64, i64, i64, i64),
        /// What is wrong.
        message: String,
    },
    /// An error from the core crate (camera validation, files).
    #[error(transparent)]
    Core(#[from] CoreError),
}

/// Result alias of the stereo crate.
pub type Result<T> = std::result::Result<T, StereoError>;

pub(crate) fn param(name: &'static str, message: impl Into<String>) -> StereoError {
    StereoError::InvalidParam { name, message: message.into() }
}
