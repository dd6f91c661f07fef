//! tubeloc-calib: AprilTag detection, tag-pair ground-truth tube poses, and intrinsic and
//! multi-camera calibration with rig files (tubeloc JSON, OpenCV YAML, ROS camera_info, kalibr
//! camchain).
//!
//! - [`detect`]: wrapper of the AprilTag 3 detector (`apriltag` crate); corners in the tubeloc /
//!   OpenCV pixel convention (pixel centres at integers); [`batch`]: many files at once.
//! - [`mount`] + [`tagpose`]: the tag mount of `data/tag_mount.toml` and `T_cam_tube` from the
//!   tag pair (PnP + Levenberg-Marquardt, covariance, single-tag fallback flagged).
//! - [`calibrate`]: Zhang initialization, bundle adjustment of intrinsics, distortion and
//!   board poses, outlier rejection, multi-camera extrinsics; [`views`] reads calibration sets.
//! - [`yaml`]: OpenCV FileStorage YAML rig files; [`interchange`]: ROS `camera_info` and kalibr
//!   camchain files, and [`read_rig`], the one reader of every format.
//! - [`lm`], [`geometry`]: the least-squares solver and projective helpers.
#![warn(missing_docs)]

pub mod batch;
pub mod calibrate;
pub mod detect;
pub mod error;
pub mod geometry;
pub mod grey;
pub mod interchange;
pub mod lm;
pub mod mount;
pub mod tagpose;
pub mod views;
pub mod yaml;

pub use batch::detect_files;
pub use calibrate::{calibrate, CalibrationInput, CalibrationOptions, CameraCalibration, CameraSpec, Observation, RigCalibration};
pub use detect::{DetectorConfig, TagDetection, TagDetector, TagFamily};
pub use error::CalibError;
pub use interchange::{read_camera, read_rig, RigFormat};
pub use mount::{MountedTag, TagMount};
pub use tagpose::{estimate_tube_pose, TagPoseEstimate};
pub use views::{load_calib_set, load_calib_set_reporting, Board, CornerSource, LoadedSet};
pub use yaml::{load_rig_yaml, rig_from_yaml, rig_to_yaml, save_rig_yaml};
