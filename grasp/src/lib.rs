//! tubeloc-grasp: grasps of located tubes checked for collisions with the scene (parry3d).
//!
//! The gripper ([`GripperModel`], `data/gripper.toml`) is two finger boxes and a palm box in
//! the grasp frame (origin on the tube axis, +x along the axis, +z the approach, +y the closing
//! direction; metres). The scene ([`Scene`]) is what is known around a tube in the camera frame
//! (OpenCV: x right, y down, z forward; metres): the ground plane ([`GroundPlane`], `n · X = d`,
//! `n` up), the other located tubes as cylinders of their sections ([`TubeSolid`]), and with
//! stereo the terrain near the tube as cuboid columns of a height map ([`Terrain`]).
//!
//! [`GraspPlanner::check`] samples grasps along the tube's body section and approach tilts about
//! its axis, rejects those whose fingers or palm (swept along the last approach segment) come
//! closer to the scene than the minimum clearance, and returns the best by clearance as a
//! [`GraspCheck`]. [`overlapping_tubes`] finds located tubes whose solids interpenetrate (two
//! such tubes cannot both be right).
//!
//! Distances are parry3d's in f64 (`parry3d-f64`): the camera frame's metres at 1 to 3 m range
//! with millimetre clearances, the workspace's nalgebra `f64` types without conversion.
//!
//! ```
//! use nalgebra::Vector3;
//! use tubeloc_core::{GroundPlane, TubeAxisPose, TubeModel};
//! use tubeloc_grasp::{GraspPlanner, GripperModel, PlannerSettings, Scene};
//!
//! // A tube lying on flat ground 1.5 m below a level camera, 1 m ahead, across the view.
//! let ground = GroundPlane::new(Vector3::new(0.0, -1.0, 0.0), -1.5).unwrap();
//! let tube = TubeAxisPose::new(0, 0.9, Vector3::new(0.0, 1.5 - 0.0115, 1.0), Vector3::x(), 0.9).unwrap();
//! let planner = GraspPlanner::new(GripperModel::default(), PlannerSettings::default(), &TubeModel::default()).unwrap();
//! let check = planner.check(&tube, &ground.normal, &Scene { ground, tubes: &[], terrain: None });
//! assert!(check.feasible && !check.changed && !check.terrain_checked);
//! // Fingertips 3 mm past the axis, the axis 11.5 mm above the ground: 8.5 mm to spare.
//! assert!((check.clearance_mm - 8.5).abs() < 1e-6);
//! ```
#![warn(missing_docs)]

pub mod gripper;
pub mod planner;
pub mod solid;
pub mod terrain;

pub use gripper::{GripperModel, GripperPart, DEFAULT_GRIPPER_TOML};
pub use planner::{GraspCheck, GraspPlanner, PlannerSettings, RejectionCounts, Scene};
pub use solid::{overlapping_tubes, TubeSolid};
pub use terrain::{Terrain, TerrainSettings};
pub use tubeloc_core::GroundPlane;
