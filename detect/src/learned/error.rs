//! Typed errors of the learned segmenter.

use std::path::PathBuf;

/// Everything that can go wrong while building, training, saving, loading or running the model.
#[derive(Debug, thiserror::Error)]
pub enum LearnedError {
    /// A file could not be read or written.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error (in the message, not a `source()`: chains print it once).
        error: std::io::Error,
    },
    /// A weights file is not a valid tubeloc model (corrupt, truncated, wrong format version,
    /// checksum mismatch, missing or mis-shaped tensors).
    #[error("{path}: invalid model file: {msg}")]
    BadModel {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// A dataset could not be used for training.
    #[error("dataset {path}: {msg}")]
    Dataset {
        /// The dataset directory or file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// Invalid caller input (image size, parameters).
    #[error("invalid input: {0}")]
    Invalid(String),
    /// An error inside the tensor framework (candle).
    #[error("tensor framework: {0}")]
    Tensor(#[from] candle_core::Error),
}

impl LearnedError {
    pub(crate) fn bad_model(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        LearnedError::BadModel { path: path.into(), msg: msg.into() }
    }
}
