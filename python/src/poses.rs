//! `tubeloc.Tube`: one refined tube pose (and, from `Locator.locate`, its grasp frames,
//! probability and status) with numpy arrays.

use nalgebra::Vector3;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyAnyMethods;
use tubeloc_core::{Pose, TubeAxisPose};
use tubeloc_pipeline::LocatedTube;

/// One tube pose in the camera frame (OpenCV: x right, y down, z forward; metres).
///
/// From `Locator.locate` also its grasp frames, probability of being a tube and status
/// (`located`, or why not: `fit_failed`, `low_probability`, `weak_pose_evidence`, ...) and
/// pose evidence; from `refine` these are None.
#[pyclass(name = "Tube", module = "tubeloc", frozen)]
pub struct PyTube {
    /// COCO image id of the detection it was refined from.
    #[pyo3(get)]
    image_id: u64,
    /// Detector score of the detection it was refined from.
    #[pyo3(get)]
    score: f64,
    /// Axis midpoint, camera frame, metres: array of shape (3,).
    #[pyo3(get)]
    centre: Py<PyAny>,
    /// Unit axis direction toward the seal end (camera frame): shape (3,).
    #[pyo3(get)]
    axis: Py<PyAny>,
    /// Unit direction of the seal end, as decided from the image (camera frame): shape (3,).
    #[pyo3(get)]
    end_direction: Py<PyAny>,
    /// Confidence in `end_direction`, in [0.5, 1].
    #[pyo3(get)]
    end_confidence: f64,
    /// Covariance of (centre x, y, z in m; axis tilts in rad) from the fit: shape (5, 5).
    #[pyo3(get)]
    covariance: Py<PyAny>,
    /// Whether the fit converged.
    #[pyo3(get)]
    converged: bool,
    /// Why the fit failed (e.g. `diverged`), or None.
    #[pyo3(get)]
    failure: Option<String>,
    /// The failure's message, or None.
    #[pyo3(get)]
    failure_message: Option<String>,
    /// Probability of a tube (the score through the model's calibration); None from `refine`.
    #[pyo3(get)]
    probability: Option<f64>,
    /// Probability that the pose is a tube from the detector's score and the fit's evidence
    /// (the learned model's pose evidence); None without one, for unconverged fits and from
    /// `refine`.
    #[pyo3(get)]
    pose_evidence: Option<f64>,
    /// How strongly the edges along the tube's limbs go on past its ends, against along its
    /// body (about 0.15 for a tube, 0.5-2 for a rim); None for unconverged fits, where an end
    /// lies out of the image, and from `refine`.
    #[pyo3(get)]
    limb_continuation: Option<f64>,
    /// `located`, or why not (`fit_failed`, `low_probability`, `weak_pose_evidence`,
    /// `limbs_continue`, `intersects_tube`, `underexposed`, `in_ignored_region`); None from
    /// `refine`.
    #[pyo3(get)]
    status: Option<String>,
    /// Grasp frame in the camera frame, 4x4 homogeneous (origin at the centre, +x along the
    /// axis, +z the approach, +y the closing direction); None from `refine`.
    #[pyo3(get)]
    t_cam_grasp: Option<Py<PyAny>>,
    /// The grasp frame in the rig frame, 4x4; None from `refine`.
    #[pyo3(get)]
    t_rig_grasp: Option<Py<PyAny>>,
    /// The pose as the CLI writes it (JSON text of one entry of `tubes` in `tubeloc locate`'s
    /// output, or of `tubeloc refine`'s array).
    json: String,
}

fn vec3(py: Python<'_>, v: &Vector3<f64>) -> Py<PyAny> {
    PyArray1::from_slice(py, v.as_slice()).into_any().unbind()
}

fn matrix4(py: Python<'_>, p: &Pose) -> Py<PyAny> {
    let (r, t) = (p.rotation(), p.translation());
    let rows: Vec<Vec<f64>> = (0..4).map(|i| if i < 3 { vec![r[(i, 0)], r[(i, 1)], r[(i, 2)], t[i]] } else { vec![0.0, 0.0, 0.0, 1.0] }).collect();
    PyArray2::from_vec2(py, &rows).expect("4x4").into_any().unbind()
}

impl PyTube {
    /// A refined pose (no grasp frames, probability or status).
    pub fn from_pose(py: Python<'_>, p: &TubeAxisPose) -> Self {
        let json = serde_json::to_string(p).expect("a pose serializes");
        Self::build(py, p, None, None, json)
    }

    /// A tube of `Locator.locate` with its status.
    pub fn from_located(py: Python<'_>, t: &LocatedTube, status: &str) -> Self {
        let mut v = serde_json::to_value(t).expect("a tube serializes");
        v["status"] = serde_json::Value::from(status);
        let json = v.to_string();
        Self::build(py, &t.pose, Some((t, status)), Some(t.probability), json)
    }

    fn build(py: Python<'_>, p: &TubeAxisPose, located: Option<(&LocatedTube, &str)>, probability: Option<f64>, json: String) -> Self {
        let cov: Vec<Vec<f64>> = p.covariance.iter().map(|r| r.to_vec()).collect();
        let reason = p.failure.as_ref().map(|f| serde_json::to_value(f.reason).ok().and_then(|v| v.as_str().map(str::to_string)).unwrap_or_default());
        PyTube {
            image_id: p.image_id,
            score: p.score,
            centre: vec3(py, &p.centre),
            axis: vec3(py, &p.axis),
            end_direction: vec3(py, &p.end_direction),
            end_confidence: p.end_confidence,
            covariance: PyArray2::from_vec2(py, &cov).expect("5x5").into_any().unbind(),
            converged: p.converged,
            failure: reason,
            failure_message: p.failure.as_ref().map(|f| f.message.clone()),
            probability,
            pose_evidence: located.and_then(|(t, _)| t.pose_evidence),
            limb_continuation: located.and_then(|(t, _)| t.limb_continuation),
            status: located.map(|(_, s)| s.to_string()),
            t_cam_grasp: located.map(|(t, _)| matrix4(py, &t.t_cam_grasp)),
            t_rig_grasp: located.map(|(t, _)| matrix4(py, &t.t_rig_grasp)),
            json,
        }
    }
}

#[pymethods]
impl PyTube {
    /// The pose as a dict in the CLI's JSON form (one entry of `tubes` in `tubeloc locate`'s
    /// poses file, or of `tubeloc refine`'s array), with every field the file has.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        py.import("json")?.call_method1("loads", (self.json.as_str(),))
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let c = self.centre.bind(py).extract::<Vec<f64>>().unwrap_or_default();
        format!(
            "tubeloc.Tube(status={:?}, converged={}, score={:.3}, centre_m=[{:.4}, {:.4}, {:.4}])",
            self.status.as_deref().unwrap_or("-"),
            self.converged,
            self.score,
            c.first().unwrap_or(&f64::NAN),
            c.get(1).unwrap_or(&f64::NAN),
            c.get(2).unwrap_or(&f64::NAN)
        )
    }
}

/// pose_evidence(tube, evidence="shipped") -> float
///
/// The probability that a refined tube (a `Tube` from `refine` or `Locator.locate`) is a tube,
/// from its detector score and its fit's evidence (the share of contour samples on an edge,
/// their number, the seal-end confidence, the axis's sigma): the score `tubeloc refine
/// --snapped-out --pose-evidence` gives its snapped detection. `evidence`: `shipped` (fitted
/// on the shipped model's detections of real validation composites) or a file written by
/// `tubeloc eval --fit-pose-evidence`.
#[pyfunction]
#[pyo3(signature = (tube, evidence = "shipped"))]
pub fn pose_evidence(tube: PyRef<'_, PyTube>, evidence: &str) -> PyResult<f64> {
    let model = tubeloc_pipeline::shipped::pose_evidence(evidence).map_err(|e| crate::error::chain_to_py(&e))?;
    let pose: TubeAxisPose = serde_json::from_str(&tube.json).map_err(crate::error::to_py)?;
    Ok(model.probability(&pose))
}
