//! Core types of tubeloc, shared by every other crate.
//!
//! Conventions (see the README): the camera frame is OpenCV's (x right, y down, z forward),
//! pixel centres sit at integer coordinates, the world frame is z up in metres, and `T_a_b`
//! maps points of frame `b` into frame `a`. The tube frame has its origin at the tube's centre
//! and +z along the axis toward the seal end.
#![warn(missing_docs)]

pub mod assumed_view;
pub mod bit_depth;
pub mod camera;
pub mod coco;
pub mod confidence;
pub mod detection;
pub mod error;
pub mod field_range;
pub mod files;
pub mod geometry;
pub mod ground;
pub mod heap;
pub mod image_file;
pub mod mask;
pub mod monochrome;
pub mod odl;
pub mod plane;
pub mod pose;
pub mod pose_evidence;
pub mod rectification;
pub mod rig;
pub mod rover_camera;
pub mod tube;
pub mod tube_pose;

pub use assumed_view::{AssumedView, FrameView};
pub use camera::{CameraModel, Distortion};
pub use coco::{CocoAnnotation, CocoCategory, CocoDataset, CocoImage, CocoResult, Segmentation};
pub use confidence::ScoreCalibration;
pub use detection::{AxisSeed, DetectionSource, TubeDetection};
pub use error::CoreError;
pub use ground::GroundPlane;
pub use mask::{keep_by_iou, BinaryMask, BoundedMask, MaskWindow, Rle};
pub use plane::Plane;
pub use pose::Pose;
pub use pose_evidence::PoseEvidence;
pub use rectification::PairRectification;
pub use rig::{Rig, RigCamera};
pub use rover_camera::RoverCamera;
pub use tube::{TubeMaterial, TubeMesh, TubeModel, TubeSection};
pub use tube_pose::{FailureReason, RefineFailure, ResidualStats, TubeAxisPose};
