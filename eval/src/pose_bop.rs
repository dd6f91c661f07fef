//! BOP pose errors MSSD and MSPD with the tube's symmetries, and their average recalls.
//!
//! Definitions of the BOP challenge 2019/2020 (Hodan et al.), for an estimated pose
//! `P_e = (R_e, t_e)`, the ground truth `P_g`, model points `M` and symmetry set `S`:
//!
//! ```text
//! MSSD = min_{S ∈ S} max_{x ∈ M} ‖P_e x − P_g S x‖₂                  (metres; reported in mm)
//! MSPD = min_{S ∈ S} max_{x ∈ M} ‖π(P_e x) − π(P_g S x)‖₂             (pixels)
//! ```
//!
//! `π` is the full camera model (with distortion; BOP's own data is undistorted, where this is
//! the same). The tube is symmetric under any rotation about its axis (tube frame +z); that
//! continuous symmetry is discretized every `step_deg` as BOP does. The "flip" set adds the
//! 180° rotation about the tube frame's x axis composed with each of those rotations (the two
//! ends exchanged), which the real tube only approximately has.
//!
//! An estimate is correct at threshold τ when its error is `< τ`. Recall at τ is the number of
//! correct matched estimates over the number of ground-truth instances (an unmatched truth is a
//! miss); the average recall is the mean over the standard thresholds:
//! MSSD τ = 0.05, 0.10, …, 0.50 × object diameter; MSPD τ = 5, 10, …, 50 px × (image width / 640).

use crate::pose::PoseEvalError;
use nalgebra::{Matrix3, Point2, Point3, Rotation3, Vector3};
use rayon::prelude::*;
use tubeloc_core::{CameraModel, Pose, TubeModel};

/// Points sampled on the model surface (tube frame, metres) and the object diameter.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelPoints {
    /// Surface points, tube frame, metres.
    pub points: Vec<Point3<f64>>,
    /// Largest distance between two model points, metres (BOP's object diameter).
    pub diameter: f64,
}

impl ModelPoints {
    /// Wraps given points (e.g. mesh vertices), computing the diameter by brute force.
    pub fn from_points(points: Vec<Point3<f64>>) -> Result<Self, PoseEvalError> {
        if points.is_empty() {
            return Err(PoseEvalError::invalid("model points", "no points"));
        }
        if points.iter().any(|p| !p.coords.iter().all(|v| v.is_finite())) {
            return Err(PoseEvalError::invalid("model points", "non-finite coordinate"));
        }
        let diameter = points.par_iter().enumerate().map(|(i, p)| points[i + 1..].iter().map(|q| (p - q).norm_squared()).fold(0.0, f64::max)).reduce(|| 0.0, f64::max).sqrt();
        Ok(ModelPoints { points, diameter })
    }

    /// Samples the surface of a parametric tube about every `spacing` metres: rings on each
    /// section's mantle, and annuli on the end faces and on the steps between sections. Every
    /// ring has its points evenly spread in angle, so their centroid lies on the axis.
    pub fn from_tube(model: &TubeModel, spacing: f64) -> Result<Self, PoseEvalError> {
        if !(spacing.is_finite() && spacing > 0.0) {
            return Err(PoseEvalError::invalid("spacing", format!("must be a positive length in metres, got {spacing}")));
        }
        model.validate().map_err(|e| PoseEvalError::invalid("tube model", e.to_string()))?;
        let mut pts = Vec::new();
        let ring = |pts: &mut Vec<Point3<f64>>, r: f64, z: f64| {
            if r <= 0.0 {
                pts.push(Point3::new(0.0, 0.0, z));
                return;
            }
            let n = ((std::f64::consts::TAU * r / spacing).ceil() as usize).max(8);
            for k in 0..n {
                let a = std::f64::consts::TAU * k as f64 / n as f64;
                pts.push(Point3::new(r * a.cos(), r * a.sin(), z));
            }
        };
        let annulus = |pts: &mut Vec<Point3<f64>>, r0: f64, r1: f64, z: f64| {
            let (lo, hi) = (r0.min(r1), r0.max(r1));
            let n = ((hi - lo) / spacing).ceil().max(1.0) as usize;
            for k in 0..n {
                ring(pts, lo + (hi - lo) * k as f64 / n as f64, z);
            }
        };
        for s in &model.sections {
            let (z0, z1) = model.section_z_in_tube_frame(s);
            let n = ((z1 - z0) / spacing).ceil().max(1.0) as usize;
            for k in 0..=n {
                ring(&mut pts, s.radius, z0 + (z1 - z0) * k as f64 / n as f64);
            }
        }
        // End faces (discs) and the steps between consecutive sections.
        let first = &model.sections[0];
        annulus(&mut pts, 0.0, first.radius, model.section_z_in_tube_frame(first).0);
        let last = &model.sections[model.sections.len() - 1];
        annulus(&mut pts, 0.0, last.radius, model.section_z_in_tube_frame(last).1);
        for w in model.sections.windows(2) {
            if (w[0].radius - w[1].radius).abs() > 1e-12 {
                annulus(&mut pts, w[0].radius, w[1].radius, model.section_z_in_tube_frame(&w[0]).1);
            }
        }
        Self::from_points(pts)
    }
}

/// A discretized symmetry set of the tube, as rotations of the tube frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Symmetries {
    /// The rotations `S` (identity first).
    pub rotations: Vec<Rotation3<f64>>,
}

impl Symmetries {
    /// Rotations about +z every `step_deg` (rounded so that the steps divide 360°); with `flip`,
    /// also each of them followed by 180° about x: `S = R_x(π) R_z(θ)`.
    pub fn tube(step_deg: f64, flip: bool) -> Result<Self, PoseEvalError> {
        if !(step_deg.is_finite() && step_deg > 0.0 && step_deg <= 360.0) {
            return Err(PoseEvalError::invalid("symmetry step", format!("must be in (0, 360] degrees, got {step_deg}")));
        }
        let n = (360.0 / step_deg).round().max(1.0) as usize;
        let axial: Vec<Rotation3<f64>> = (0..n).map(|k| Rotation3::from_axis_angle(&Vector3::z_axis(), std::f64::consts::TAU * k as f64 / n as f64)).collect();
        let mut rotations = axial.clone();
        if flip {
            let fx = Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
            rotations.extend(axial.iter().map(|r| fx * r));
        }
        Ok(Symmetries { rotations })
    }

    /// Only the identity (an asymmetric object).
    pub fn none() -> Self {
        Symmetries { rotations: vec![Rotation3::identity()] }
    }
}

/// MSSD in metres (definition in the module documentation).
pub fn mssd(est: &Pose, gt: &Pose, model: &ModelPoints, sym: &Symmetries) -> f64 {
    let (re, rg) = (est.rotation(), gt.rotation());
    let b = est.translation() - gt.translation();
    let mut best = f64::INFINITY;
    for s in &sym.rotations {
        let a: Matrix3<f64> = re - rg * s.matrix();
        let best2 = best * best;
        let mut worst = 0.0f64;
        for x in &model.points {
            worst = worst.max((a * x.coords + b).norm_squared());
            if worst >= best2 {
                break;
            }
        }
        best = best.min(worst.sqrt());
    }
    best
}

/// MSPD in pixels with `camera` (definition in the module documentation). Points at or
/// behind the camera plane give an infinite error for that symmetry.
pub fn mspd(est: &Pose, gt: &Pose, model: &ModelPoints, sym: &Symmetries, camera: &CameraModel) -> f64 {
    let proj_e: Vec<Option<Point2<f64>>> = model.points.iter().map(|x| camera.project(&est.transform_point(x))).collect();
    let rg = gt.rotation();
    let tg = gt.translation();
    let mut best = f64::INFINITY;
    for s in &sym.rotations {
        let r: Matrix3<f64> = rg * s.matrix();
        let best2 = best * best;
        let mut worst = 0.0f64;
        for (x, pe) in model.points.iter().zip(&proj_e) {
            let pg = camera.project(&Point3::from(r * x.coords + tg));
            let e2 = match (pe, pg) {
                (Some(a), Some(b)) => (a - b).norm_squared(),
                _ => f64::INFINITY,
            };
            worst = worst.max(e2);
            if worst >= best2 {
                break;
            }
        }
        best = best.min(worst.sqrt());
    }
    best
}

/// BOP MSSD thresholds in metres: `0.05, 0.10, …, 0.50 × diameter`.
pub fn mssd_thresholds(diameter: f64) -> Vec<f64> {
    (1..=10).map(|k| 0.05 * k as f64 * diameter).collect()
}

/// BOP MSPD thresholds in pixels for a 640-pixel-wide image: `5, 10, …, 50`; multiply by
/// `width / 640` for another width (or divide the error by it, as [`bop_recalls`] callers do).
pub fn mspd_thresholds_640() -> Vec<f64> {
    (1..=10).map(|k| 5.0 * k as f64).collect()
}

/// Recall at each threshold: `#{errors < τ} / n_truths` (an error of a matched pair; unmatched
/// truths simply have no error). Zero truths give recalls of 0.
pub fn bop_recalls(errors: &[f64], n_truths: usize, thresholds: &[f64]) -> Vec<f64> {
    thresholds.iter().map(|&t| if n_truths == 0 { 0.0 } else { errors.iter().filter(|&&e| e < t).count() as f64 / n_truths as f64 }).collect()
}

/// Mean of the recalls at the thresholds (BOP's AR for one error function).
pub fn average_recall(errors: &[f64], n_truths: usize, thresholds: &[f64]) -> f64 {
    let r = bop_recalls(errors, n_truths, thresholds);
    if r.is_empty() {
        0.0
    } else {
        r.iter().sum::<f64>() / r.len() as f64
    }
}
