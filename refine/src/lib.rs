//! tubeloc-refine: edge-based 6D pose refinement of sample tubes with a cylinder model.
//!
//! A detection ([`TubeDetection`]: Line2D template pose, learned mask axis, or box) seeds a
//! robust Levenberg-Marquardt fit of the tube's projected occluding contour
//! ([`contour`]) to image edges ([`edges`]), coarse to fine over an image pyramid, with an
//! optional stereo term ([`Scene`]). The fitted parameters are the centre and the axis
//! direction (rotation about the axis is not observable and not optimized). Which end is the
//! seal end is decided afterwards by fitting both end hypotheses and comparing their edge
//! support, or from the colours. The output is a [`TubeAxisPose`] with a flip-free axis,
//! covariance, residual statistics and a failure reason instead of NaN when the fit fails.
//!
//! The settings are [`RefineConfig`], in groups ([`settings`]); a [`Refiner`] validates them
//! and resolves them once per seed kind ([`SeedKind`], [`FitSettings`]).
//!
//! [`TubeDetection`]: tubeloc_core::TubeDetection
//! [`TubeAxisPose`]: tubeloc_core::TubeAxisPose
#![warn(missing_docs)]

pub mod contour;
mod detection_seed;
pub mod duplicates;
pub mod edges;
mod end_decision;
mod error;
mod fit;
pub mod hidden_end;
mod jacobian;
pub mod limb_continuation;
pub mod local_ground;
mod mask_check;
mod model;
mod mono;
mod normal_equations;
pub mod photo;
pub mod priors;
mod refiner;
pub mod rims;
mod robust;
mod scene;
pub mod seal_end;
mod search;
pub mod seed;
mod seed_fit;
mod seed_policy;
pub mod settings;
pub mod silhouette;
pub mod stereo_stage;
pub mod two_view;
mod validation;

pub use contour::AxisState;
pub use error::RefineError;
pub use fit::FitResult;
pub use model::CylinderModel;
pub use refiner::{stereo_supports_fit, RefineInput, Refiner, MIN_STEREO_INLIERS};
pub use scene::Scene;
pub use seed::{seed_from_detection, GroundPlane, Seed};
pub use seed_policy::{FitSettings, SeedKind};
pub use settings::RefineConfig;
