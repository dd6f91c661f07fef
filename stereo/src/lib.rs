//! tubeloc-stereo: rectification, semi-global matching and triangulation.
//!
//! Public API (frames follow OpenCV: x right, y down, z forward; disparity `d = x_left - x_right`
//! in pixels of the rectified images; invalid disparities are `f32::NAN`):
//!
//! - [`rectify::StereoRectification::new`]`(&CameraModel, &CameraModel, &Pose /*T_left_right*/)`
//!   rotates both cameras to a common plane (Bouguet-style), gives the rectified camera, the
//!   projection matrices `P1`, `P2`, the disparity-to-depth matrix `Q`, remap tables and valid
//!   regions; [`rectify::StereoRectification::rectify_pair`] remaps an image pair.
//! - [`sgm::disparity`]`(&Plane<u8>, &Plane<u8>, &SgmParams) -> Result<Plane<f32>>`:
//!   census-cost semi-global matching (8 or 4 paths); [`sgm::SgmMatcher`] reuses buffers;
//!   [`region::disparity_regions`] matches only inside regions of interest.
//! - [`triangulate::triangulate`]`(&Plane<f32>, &RectifiedGeometry, sigma_d)`: 3D points in the
//!   rectified left frame with `σ_Z = Z² σ_d / (f B)`; [`triangulate::StereoPoint`].
//! - [`metrics`]: Middlebury-style bad-N and mean absolute error on non-occluded pixels.
//! - [`pair_eval`]: scores against exact disparity (valid and tube pixels) and distances of
//!   triangulated tube points to the true tube surface.
//! - [`io`]: PFM and 16-bit fixed-point disparity files, colour previews.
#![warn(missing_docs)]

pub(crate) mod aggregate;
pub mod census;
pub(crate) mod cost;
pub mod error;
pub mod io;
pub mod metrics;
pub mod pair_eval;
pub mod post;
pub mod region;
pub mod sgm;
#[doc(hidden)]
pub mod simd;

pub use error::{Result, StereoError};
pub use region::{disparity_regions, Roi};
pub use sgm::{disparity, Paths, SgmMatcher, SgmParams};
pub mod rectify;
pub mod synthetic;
pub mod triangulate;

pub use rectify::StereoRectification;
pub use triangulate::{triangulate, RectifiedGeometry, StereoPoint};
