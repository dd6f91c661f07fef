//! Tube pose errors on the axis line: angle, perpendicular and along-axis offsets, end direction.
//!
//! A tube is (nearly) rotationally symmetric about its axis, so its grasp-relevant pose is the
//! axis line: a centre `c` (metres, camera frame) and a unit axis `a` (tube frame +z, toward the
//! seal end). For an estimate `(c_e, a_e)` and ground truth `(c_g, a_g)`:
//!
//! ```text
//! axis angle      θ = acos(|a_e · a_g|)              (degrees, flip-invariant, in [0, 90])
//! centre offset   d = c_e - c_g
//! along-axis      s = d · a_g                         (mm, signed, + toward the true seal end)
//! perpendicular   p = |d - s a_g|                     (mm, distance of c_e to the true axis line)
//! end correct     a_e · a_g > 0
//! ```
//!
//! BOP's MSSD/MSPD live in [`crate::pose_bop`], matching in [`crate::pose_match`], summaries and
//! the whole evaluation in [`crate::pose_summary`].

use nalgebra::{Point3, Unit, Vector3};
use serde::{Deserialize, Serialize};
use tubeloc_core::{Pose, TubeAxisPose};

/// Errors of the pose metrics (invalid inputs; never a panic).
#[derive(Debug, thiserror::Error)]
pub enum PoseEvalError {
    /// An input value is out of range (names the value).
    #[error("invalid {what}: {message}")]
    Invalid {
        /// The value concerned.
        what: String,
        /// What is wrong.
        message: String,
    },
}

impl PoseEvalError {
    pub(crate) fn invalid(what: impl Into<String>, message: impl Into<String>) -> Self {
        PoseEvalError::Invalid { what: what.into(), message: message.into() }
    }
}

/// A tube axis line in one frame (usually the camera frame): centre in metres and a unit
/// direction (the tube frame's +z, toward the seal end, when known).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisLine {
    /// Centre of the tube, metres.
    pub centre: Point3<f64>,
    /// Unit axis direction.
    pub axis: Unit<Vector3<f64>>,
}

impl AxisLine {
    /// A line from a centre (metres) and a non-zero, finite direction (normalized here).
    pub fn new(centre: Point3<f64>, axis: Vector3<f64>) -> Result<Self, PoseEvalError> {
        if !centre.coords.iter().chain(axis.iter()).all(|v| v.is_finite()) {
            return Err(PoseEvalError::invalid("axis line", "non-finite centre or axis"));
        }
        let axis = Unit::try_new(axis, 1e-12).ok_or_else(|| PoseEvalError::invalid("axis line", "zero-length axis"))?;
        Ok(AxisLine { centre, axis })
    }

    /// The axis line of a tube pose `T_cam_tube`: centre = translation, axis = R e_z.
    pub fn from_pose(t_cam_tube: &Pose) -> Self {
        let axis = Unit::new_normalize(t_cam_tube.transform_vector(&Vector3::z()));
        AxisLine { centre: Point3::from(t_cam_tube.translation()), axis }
    }

    /// The axis line of a refined grasp pose, directed along its `end_direction`.
    pub fn from_axis_pose(p: &TubeAxisPose) -> Result<Self, PoseEvalError> {
        AxisLine::new(Point3::from(p.centre), p.end_direction)
    }
}

/// Axis-line errors of one estimate against its ground truth.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisError {
    /// `acos(|a_e · a_g|)` in degrees, in `[0, 90]` (a flipped estimate has zero error).
    pub axis_angle_deg: f64,
    /// Distance of the estimated centre to the true axis line, mm.
    pub perpendicular_mm: f64,
    /// Signed offset of the estimated centre along the true axis, mm (+ toward the seal end).
    pub along_axis_mm: f64,
    /// Euclidean distance between the centres, mm.
    pub centre_distance_mm: f64,
    /// True when the estimated axis points to the same end as the truth (`a_e · a_g > 0`).
    pub end_correct: bool,
}

/// Axis-line errors of `est` against `gt` (formulas in the module documentation).
pub fn axis_error(est: &AxisLine, gt: &AxisLine) -> AxisError {
    let dot = est.axis.dot(&gt.axis);
    let axis_angle_deg = dot.abs().clamp(0.0, 1.0).acos().to_degrees();
    let d = est.centre - gt.centre;
    let along = d.dot(&gt.axis);
    let perp = (d - gt.axis.into_inner() * along).norm();
    AxisError { axis_angle_deg, perpendicular_mm: perp * 1e3, along_axis_mm: along * 1e3, centre_distance_mm: d.norm() * 1e3, end_correct: dot > 0.0 }
}

/// [`axis_error`] of two tube poses `T_cam_tube`.
pub fn pose_axis_error(est: &Pose, gt: &Pose) -> AxisError {
    axis_error(&AxisLine::from_pose(est), &AxisLine::from_pose(gt))
}
