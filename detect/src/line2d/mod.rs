//! Line2D (LINE-2D, Hinterstoisser et al. 2012): template matching on quantized gradient
//! orientations with precomputed response maps, templates rendered from the tube model.
//!
//! Pipeline (one module per step):
//! - [`render`]: exact analytic ray casting of the parametric tube (coaxial capped cylinders)
//!   into a silhouette + depth image.
//! - [`mesh`]: the same from a triangle mesh of the tube (the CAD model's OBJ) by rasterization.
//! - [`viewpoints`]: viewpoints on a subdivided icosahedron (upper hemisphere), in-plane
//!   rotations and distances; views equal up to the tube's axial symmetry are deduplicated.
//! - [`gradient`]: colour gradients (strongest channel, Sobel), orientation quantized into 8 bins
//!   modulo 180 degrees, 3x3 majority vote, magnitude threshold.
//! - [`template`]: contour features of a silhouette (spread-out selection) on a 2-level pyramid,
//!   and the [`TemplateLibrary`] built from the tube model.
//! - [`format`](mod@format): the versioned, checksummed binary library file (`.tlt`).
//! - [`response`]: spreading over `T`, the 8 response maps via two 4-bit lookup tables and the
//!   linearized memories.
//! - [`params`]: [`MatchParams`], the detector's settings and their chosen defaults.
//! - [`matching`]: coarse-to-fine matching with saturation-free integer accumulation, rayon
//!   across templates.
//! - [`nms`]: non-maximum suppression by placed silhouettes, and re-ranking within clusters.
//! - [`ground`]: ground consistency: where the ground plane is known, a match's template
//!   distance must agree with the ground's distance along its ray.
//! - [`verify`]: radiometric verification (bright silhouette against a ring around it)
//!   rescoring raw matches before NMS.
//! - [`classify`]: the clutter verifier: per-detection features (contrast against each long
//!   side, surface texture, edge strength...) and a logistic classifier fitted on composites of
//!   rendered tubes on real training frames; its probability is the detection score.
//! - [`detection`]: [`Line2dDetection`] with the coarse 6D pose and COCO output.
//! - [`detector`]: [`Line2dDetector`], the library and parameters run end to end on an image.

pub mod classify;
pub mod detection;
pub mod detector;
pub mod format;
pub mod gradient;
pub mod ground;
pub mod mask;
pub mod matching;
pub mod mesh;
pub mod nms;
pub mod params;
pub mod render;
pub mod response;
pub mod template;
pub mod verify;
pub mod viewpoints;

pub use classify::Verifier;
pub use detection::Line2dDetection;
pub use detector::Line2dDetector;
pub use gradient::GradientParams;
pub use ground::GroundRange;
pub use params::MatchParams;
pub use render::{render_silhouette, Silhouette};
pub use template::{Feature, LibraryEstimate, LibraryParams, Template, TemplateLevel, TemplateLibrary};
pub use verify::VerifyParams;
pub use viewpoints::{ViewEstimate, ViewParams, ViewSpec};

use std::path::PathBuf;

/// Number of quantized orientations (bins of 22.5 degrees over 0..180 degrees).
pub const N_ORI: usize = 8;

/// Highest per-feature similarity: `floor(4 |cos(0)|)`.
pub const SIM_MAX: u32 = 4;

/// Errors of the Line2D detector.
#[derive(Debug, thiserror::Error)]
pub enum Line2dError {
    /// A library file could not be read or written.
    #[error("{path}: {error}")]
    Io {
        /// File concerned.
        path: PathBuf,
        /// Underlying error (in the message, not a `source()`: chains print it once).
        error: std::io::Error,
    },
    /// A library file is not a valid template library (magic, version, length, checksum...).
    #[error("{path}: {message}")]
    Format {
        /// File concerned.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A parameter or input is out of range.
    #[error("invalid {what}: {message}")]
    Invalid {
        /// Name of the value.
        what: String,
        /// What is wrong with it.
        message: String,
    },
    /// An error from the core crate.
    #[error(transparent)]
    Core(#[from] tubeloc_core::CoreError),
}

impl Line2dError {
    pub(crate) fn invalid(what: impl Into<String>, message: impl Into<String>) -> Self {
        Line2dError::Invalid { what: what.into(), message: message.into() }
    }
}
