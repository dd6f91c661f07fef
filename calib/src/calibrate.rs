//! Camera and rig calibration from views of a planar target.
//!
//! 1. Per camera: plane-to-pixel homographies (normalized DLT), Zhang's closed form for
//!    `fx, fy, cx, cy` (zero skew), board poses from `K⁻¹H`, distortion starting at zero.
//! 2. Per camera bundle adjustment of intrinsics `[fx, fy, cx, cy, k1, k2, p1, p2, k3]` and board
//!    poses (Levenberg-Marquardt, [`crate::lm`]), with outlier rejection: corners whose residual
//!    norm exceeds `outlier_sigmas·σ` (σ from the median norm, `σ = median/1.1774` for a
//!    2D Gaussian) are dropped and the fit repeated.
//! 3. Several cameras: relative poses `T_ref_cam = T_ref_board·T_cam_board⁻¹` from simultaneous
//!    views, averaged (chordal mean), chained over shared views when needed; then one joint
//!    adjustment of all intrinsics, extrinsics `T_cam_ref` and per-view board poses
//!    `T_ref_board`. The rig frame is the first camera's frame.
//!
//! RMS figures: `rms_px = sqrt(Σ|r|²/N)` over corners (OpenCV's `calibrateCamera` figure) and
//! `rms_coord_px = sqrt(Σ|r|²/(2N))`, which estimates the per-coordinate corner noise.

mod reprojection;

use crate::error::CalibError;
use crate::geometry::{average_poses, check_spread, homography, intrinsics_vec, model_from_vec, pose_from_homography, pose_from_vec, pose_vec, project_cam, zhang_intrinsics};
use crate::lm::{BlockKind, Problem};
use nalgebra::{Point2, Point3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use tubeloc_core::{CameraModel, Pose, Rig, RigCamera};

/// One camera's view of the target: matching object points (target frame, metres, z = 0) and
/// image points (pixels, OpenCV convention).
#[derive(Clone, Debug)]
pub struct Observation {
    /// Index into [`CalibrationInput::cameras`].
    pub camera: usize,
    /// View (target pose) index; equal indices across cameras are simultaneous.
    pub view: usize,
    /// Target points.
    pub object: Vec<Point3<f64>>,
    /// Image points.
    pub image: Vec<Point2<f64>>,
}

/// A camera to calibrate: name and image size.
#[derive(Clone, Debug)]
pub struct CameraSpec {
    /// Name in the rig.
    pub name: String,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

/// Everything the calibration needs.
#[derive(Clone, Debug)]
pub struct CalibrationInput {
    /// Cameras; the first one defines the rig frame.
    pub cameras: Vec<CameraSpec>,
    /// Observations.
    pub observations: Vec<Observation>,
    /// Stereo pairs (left, right) to write into the rig and report baselines for.
    pub stereo_pairs: Vec<(String, String)>,
}

/// Options of [`calibrate`].
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CalibrationOptions {
    /// Minimum usable views per camera.
    pub min_views: usize,
    /// Outlier threshold in units of the robust residual σ.
    pub outlier_sigmas: f64,
    /// Rounds of outlier rejection.
    pub outlier_rounds: usize,
    /// Levenberg-Marquardt iterations per solve.
    pub max_iterations: usize,
    /// Keep `k3 = 0` (recommended for mild lenses and few views).
    pub fix_k3: bool,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        CalibrationOptions { min_views: 3, outlier_sigmas: 5.0, outlier_rounds: 3, max_iterations: 100, fix_k3: false }
    }
}

/// Residual statistics of one (camera, view).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ViewResidual {
    /// View index.
    pub view: usize,
    /// RMS residual norm over its kept corners, pixels.
    pub rms_px: f64,
    /// Corners used.
    pub points: usize,
    /// Corners rejected as outliers.
    pub outliers: usize,
}

/// Calibration of one camera.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CameraCalibration {
    /// Camera name.
    pub name: String,
    /// Estimated intrinsics and distortion.
    pub model: CameraModel,
    /// One-sigma uncertainties of `[fx, fy, cx, cy, k1, k2, p1, p2, k3]` (pixels,
    /// dimensionless; 0 for fixed ones), from `σ²·(JᵀJ)⁻¹` of the final adjustment.
    pub std: [f64; 9],
    /// `T_ref_cam`: the camera in the rig (first camera) frame.
    #[serde(rename = "T_rig_cam")]
    pub t_rig_cam: Pose,
    /// One-sigma uncertainty of `T_rig_cam` (zero for the first camera, which defines the rig
    /// frame, and for a single camera).
    #[serde(rename = "T_rig_cam_std", default)]
    pub t_rig_cam_std: PoseStd,
    /// RMS residual norm, pixels.
    pub rms_px: f64,
    /// Per-view residuals.
    pub views: Vec<ViewResidual>,
    /// Corners used.
    pub points: usize,
    /// Corners rejected.
    pub outliers: usize,
}

/// One-sigma uncertainty of a camera's pose in the rig, from the adjustment's covariance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStd {
    /// Rotation about the rig frame's x, y, z axes, radians (left perturbation of `R_rig_cam`).
    pub rotation_rad: [f64; 3],
    /// Camera position in the rig frame along x, y, z, metres.
    pub translation_m: [f64; 3],
}

impl PoseStd {
    /// Uncertainty of `T_rig_cam = T_cam_ref⁻¹` from the 6x6 covariance `cov` of the pose
    /// vector `t_cam_ref` (left update `[δω, δt]`): `δθ_rig = −Rᵀδω`,
    /// `δc = −Rᵀ(δt + [t]×δω)`.
    pub fn of_inverse(t_cam_ref: &[f64], cov: &nalgebra::DMatrix<f64>) -> PoseStd {
        let rt = Rotation3::new(Vector3::new(t_cam_ref[0], t_cam_ref[1], t_cam_ref[2])).matrix().transpose();
        let t = Vector3::new(t_cam_ref[3], t_cam_ref[4], t_cam_ref[5]);
        let mut j = nalgebra::SMatrix::<f64, 6, 6>::zeros();
        j.fixed_view_mut::<3, 3>(0, 0).copy_from(&-rt);
        j.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-rt * t.cross_matrix()));
        j.fixed_view_mut::<3, 3>(3, 3).copy_from(&-rt);
        let c = nalgebra::SMatrix::<f64, 6, 6>::from_fn(|r, k| cov[(r, k)]);
        let out = j * c * j.transpose();
        PoseStd { rotation_rad: [0, 1, 2].map(|i| out[(i, i)].max(0.0).sqrt()), translation_m: [3, 4, 5].map(|i| out[(i, i)].max(0.0).sqrt()) }
    }
}

/// Result of [`calibrate`].
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RigCalibration {
    /// The calibrated rig (rig frame = first camera).
    pub rig: Rig,
    /// Per-camera details.
    pub cameras: Vec<CameraCalibration>,
    /// Overall RMS residual norm (OpenCV's figure), pixels.
    pub rms_px: f64,
    /// Overall per-coordinate RMS, pixels (estimates the corner noise σ).
    pub rms_coord_px: f64,
    /// Baselines of the stereo pairs, metres.
    pub baselines: Vec<(String, String, f64)>,
    /// Observations left out, with the reason.
    pub skipped: Vec<String>,
    /// `T_rig_board` per view index.
    pub board_poses: BTreeMap<usize, Pose>,
}

fn transform(pose: &[f64], x: &Vector3<f64>) -> Vector3<f64> {
    Rotation3::new(Vector3::new(pose[0], pose[1], pose[2])) * x + Vector3::new(pose[3], pose[4], pose[5])
}

/// Builds and solves one adjustment. `ext[c]` is `T_cam_ref` (None: identity, fixed);
/// `poses[v]` is `T_ref_board`. Returns updated intrinsics, extrinsics, poses, plus per-point
/// squared residuals (None for rejected points) and the covariance diagonal of intrinsics.
#[allow(clippy::type_complexity)]
struct Adjustment {
    intr: Vec<[f64; 9]>,
    ext: Vec<[f64; 6]>,
    poses: BTreeMap<usize, [f64; 6]>,
    rejected: Vec<Vec<bool>>,
    std: Vec<[f64; 9]>,
    ext_std: Vec<PoseStd>,
}

fn adjust(input: &CalibrationInput, obs_idx: &[usize], adj: &mut Adjustment, opts: &CalibrationOptions, cams: &[usize]) -> Result<(), CalibError> {
    for round in 0..=opts.outlier_rounds {
        let mut p = Problem::new();
        let mut intr_b = BTreeMap::new();
        let mut ext_b = BTreeMap::new();
        let mut k3_b = BTreeMap::new();
        for &c in cams {
            intr_b.insert(c, p.add_block(adj.intr[c][..8].to_vec(), BlockKind::Euclidean, false));
            k3_b.insert(c, p.add_block(vec![if opts.fix_k3 { 0.0 } else { adj.intr[c][8] }], BlockKind::Euclidean, opts.fix_k3));
            ext_b.insert(c, p.add_block(adj.ext[c].to_vec(), BlockKind::Pose, c == cams[0]));
        }
        let mut pose_b = BTreeMap::new();
        for &o in obs_idx {
            let v = input.observations[o].view;
            pose_b.entry(v).or_insert_with(|| p.add_block(adj.poses[&v].to_vec(), BlockKind::Pose, false));
        }
        for &o in obs_idx {
            let ob = &input.observations[o];
            for (i, (x, u)) in ob.object.iter().zip(&ob.image).enumerate() {
                if adj.rejected[o][i] {
                    continue;
                }
                let (x, u) = (x.coords, *u);
                p.add_residual_with_jacobian(
                    vec![intr_b[&ob.camera], k3_b[&ob.camera], ext_b[&ob.camera], pose_b[&ob.view]],
                    2,
                    Box::new(move |b, r| reprojection::residual(b, &x, &u, r)),
                    Box::new(move |b, r, j| reprojection::residual_and_jacobian(b, &x, &u, r, j)),
                );
            }
        }
        let sol = p.solve(opts.max_iterations)?;
        for &c in cams {
            adj.intr[c][..8].copy_from_slice(&p.params[intr_b[&c]]);
            adj.intr[c][8] = p.params[k3_b[&c]][0];
            adj.ext[c].copy_from_slice(&p.params[ext_b[&c]]);
            if let Some(cov) = &sol.covariance {
                let ci = cov.block(intr_b[&c]).expect("intrinsics are free");
                for j in 0..8 {
                    adj.std[c][j] = ci[(j, j)].max(0.0).sqrt();
                }
                adj.std[c][8] = cov.block(k3_b[&c]).map(|m| m[(0, 0)].max(0.0).sqrt()).unwrap_or(0.0);
                adj.ext_std[c] = cov.block(ext_b[&c]).map(|m| PoseStd::of_inverse(&adj.ext[c], &m)).unwrap_or_default();
            }
        }
        for (v, b) in &pose_b {
            adj.poses.get_mut(v).expect("pose").copy_from_slice(&p.params[*b]);
        }
        if round == opts.outlier_rounds {
            break;
        }
        // Outlier rejection on residual norms of all points (previous outliers may return).
        let saved = adj.rejected.clone();
        for &o in obs_idx {
            adj.rejected[o].iter_mut().for_each(|r| *r = false);
        }
        let norms: Vec<(usize, usize, f64)> = obs_idx.iter().flat_map(|&o| residual_norms(input, adj, o).into_iter().enumerate().map(move |(i, n)| (o, i, n.unwrap_or(f64::INFINITY)))).collect();
        let mut sorted: Vec<f64> = norms.iter().map(|x| x.2).collect();
        sorted.sort_by(f64::total_cmp);
        let sigma = sorted[sorted.len() / 2] / 1.1774;
        let thr = (opts.outlier_sigmas * sigma).max(1e-6);
        for &(o, i, n) in &norms {
            adj.rejected[o][i] = n > thr;
        }
        if adj.rejected == saved {
            break;
        }
    }
    Ok(())
}

fn residual_norms(input: &CalibrationInput, adj: &Adjustment, o: usize) -> Vec<Option<f64>> {
    let ob = &input.observations[o];
    ob.object
        .iter()
        .zip(&ob.image)
        .enumerate()
        .map(|(i, (x, u))| {
            if adj.rejected[o][i] {
                return None;
            }
            let pc = transform(&adj.ext[ob.camera], &transform(&adj.poses[&ob.view], &x.coords));
            project_cam(&adj.intr[ob.camera], &pc).map(|q| (q - u).norm())
        })
        .collect()
}

/// Calibrates the cameras of `input` (one camera: intrinsics only; several: also extrinsics).
pub fn calibrate(input: &CalibrationInput, opts: &CalibrationOptions) -> Result<RigCalibration, CalibError> {
    let nc = input.cameras.len();
    if nc == 0 {
        return Err(CalibError::TooFew("no cameras".into()));
    }
    let mut skipped = Vec::new();
    let mut usable: Vec<Vec<usize>> = vec![Vec::new(); nc];
    let mut init_pose: BTreeMap<(usize, usize), Pose> = BTreeMap::new();
    let mut adj =
        Adjustment { intr: vec![[0.0; 9]; nc], ext: vec![[0.0; 6]; nc], poses: BTreeMap::new(), rejected: input.observations.iter().map(|o| vec![false; o.object.len()]).collect(), std: vec![[0.0; 9]; nc], ext_std: vec![PoseStd::default(); nc] };
    for (o, ob) in input.observations.iter().enumerate() {
        let name = input.cameras.get(ob.camera).map(|c| c.name.as_str()).ok_or_else(|| CalibError::invalid("observation", format!("camera index {} out of range", ob.camera)))?;
        if ob.object.len() != ob.image.len() {
            return Err(CalibError::invalid("observation", format!("camera {name} view {}: {} object points but {} image points", ob.view, ob.object.len(), ob.image.len())));
        }
        if ob.object.iter().any(|p| p.z.abs() > 1e-9) {
            return Err(CalibError::invalid("observation", format!("camera {name} view {}: target points must be planar (z = 0)", ob.view)));
        }
        let obj2: Vec<Point2<f64>> = ob.object.iter().map(|p| Point2::new(p.x, p.y)).collect();
        let check = if ob.object.len() < 6 { Err(CalibError::TooFew(format!("{} corners, need at least 6", ob.object.len()))) } else { check_spread(&obj2, "target").and_then(|_| check_spread(&ob.image, "image")) };
        match check {
            Ok(()) => usable[ob.camera].push(o),
            Err(e) => skipped.push(format!("camera {name} view {}: {e}", ob.view)),
        }
    }
    // Per-camera initialization and adjustment.
    for (c, spec) in input.cameras.iter().enumerate() {
        if usable[c].len() < opts.min_views {
            return Err(CalibError::TooFew(format!("camera {}: {} usable views, need at least {}{}", spec.name, usable[c].len(), opts.min_views, if skipped.is_empty() { String::new() } else { format!(" (skipped: {})", skipped.join("; ")) })));
        }
        let hs = usable[c]
            .iter()
            .map(|&o| {
                let ob = &input.observations[o];
                let obj2: Vec<Point2<f64>> = ob.object.iter().map(|p| Point2::new(p.x, p.y)).collect();
                homography(&obj2, &ob.image)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let k4 = zhang_intrinsics(&hs).map_err(|e| CalibError::Degenerate(format!("camera {}: {e}", spec.name)))?;
        let kinv = nalgebra::Matrix3::new(1.0 / k4[0], 0.0, -k4[2] / k4[0], 0.0, 1.0 / k4[1], -k4[3] / k4[1], 0.0, 0.0, 1.0);
        adj.intr[c] = [k4[0], k4[1], k4[2], k4[3], 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut single = Adjustment { intr: adj.intr.clone(), ext: vec![[0.0; 6]; nc], poses: BTreeMap::new(), rejected: adj.rejected.clone(), std: vec![[0.0; 9]; nc], ext_std: vec![PoseStd::default(); nc] };
        for (&o, h) in usable[c].iter().zip(&hs) {
            let pose = pose_from_homography(&(kinv * h))?;
            single.poses.insert(input.observations[o].view, pose_vec(&pose));
        }
        // Single-camera adjustment uses per-camera view indices: make them unique per camera.
        adjust(input, &usable[c], &mut single, opts, &[c])?;
        adj.intr[c] = single.intr[c];
        adj.std[c] = single.std[c];
        for &o in &usable[c] {
            adj.rejected[o] = single.rejected[o].clone();
            let v = input.observations[o].view;
            init_pose.insert((c, v), pose_from_vec(&single.poses[&v]));
        }
    }
    // Extrinsics: breadth-first from camera 0 over shared views.
    let mut t_ref_cam: Vec<Option<Pose>> = vec![None; nc];
    t_ref_cam[0] = Some(Pose::identity());
    for _ in 0..nc {
        for c in 0..nc {
            if t_ref_cam[c].is_some() {
                continue;
            }
            for a in 0..nc {
                let Some(t_ref_a) = t_ref_cam[a] else { continue };
                let rel: Vec<Pose> = init_pose.iter().filter(|((cc, _), _)| *cc == c).filter_map(|((_, v), t_c_b)| init_pose.get(&(a, *v)).map(|t_a_b| *t_a_b * t_c_b.inverse())).collect();
                if let Some(t_a_c) = average_poses(&rel) {
                    t_ref_cam[c] = Some(t_ref_a * t_a_c);
                    break;
                }
            }
        }
    }
    for (c, t) in t_ref_cam.iter().enumerate() {
        let t = t.ok_or_else(|| CalibError::Degenerate(format!("camera {} shares no simultaneous view with the other cameras; extrinsics are undetermined", input.cameras[c].name)))?;
        adj.ext[c] = pose_vec(&t.inverse());
    }
    for ((c, v), t_c_b) in &init_pose {
        if !adj.poses.contains_key(v) {
            adj.poses.insert(*v, pose_vec(&(t_ref_cam[*c].expect("set") * *t_c_b)));
        }
    }
    let all: Vec<usize> = usable.iter().flatten().copied().collect();
    if nc > 1 {
        let cams: Vec<usize> = (0..nc).collect();
        adjust(input, &all, &mut adj, opts, &cams)?;
    }
    // Report.
    let (mut sum2, mut npts) = (0.0, 0usize);
    let mut cameras = Vec::new();
    for (c, spec) in input.cameras.iter().enumerate() {
        let (mut csum, mut cn, mut cout) = (0.0, 0usize, 0usize);
        let mut views = Vec::new();
        for &o in &usable[c] {
            let norms = residual_norms(input, &adj, o);
            let kept: Vec<f64> = norms.iter().flatten().copied().collect();
            let s: f64 = kept.iter().map(|n| n * n).sum();
            let out = norms.len() - kept.len();
            views.push(ViewResidual { view: input.observations[o].view, rms_px: (s / kept.len().max(1) as f64).sqrt(), points: kept.len(), outliers: out });
            csum += s;
            cn += kept.len();
            cout += out;
        }
        sum2 += csum;
        npts += cn;
        let t_rig_cam = pose_from_vec(&adj.ext[c]).inverse();
        cameras.push(CameraCalibration {
            name: spec.name.clone(),
            model: model_from_vec(spec.width, spec.height, &adj.intr[c]),
            std: adj.std[c],
            t_rig_cam,
            t_rig_cam_std: adj.ext_std[c],
            rms_px: (csum / cn.max(1) as f64).sqrt(),
            views,
            points: cn,
            outliers: cout,
        });
    }
    let rig = Rig { cameras: cameras.iter().map(|c| RigCamera { name: c.name.clone(), model: c.model.clone(), t_rig_cam: c.t_rig_cam }).collect(), stereo_pairs: input.stereo_pairs.clone() };
    rig.validate()?;
    let baselines = input.stereo_pairs.iter().map(|(l, r)| Ok((l.clone(), r.clone(), rig.baseline(l, r)?))).collect::<Result<Vec<_>, CalibError>>()?;
    let rms_px = (sum2 / npts.max(1) as f64).sqrt();
    Ok(RigCalibration { rig, cameras, rms_px, rms_coord_px: rms_px / std::f64::consts::SQRT_2, baselines, skipped, board_poses: adj.poses.iter().map(|(v, p)| (*v, pose_from_vec(p))).collect() })
}

/// Intrinsics vector of a model (re-exported for reports).
pub fn model_vector(m: &CameraModel) -> [f64; 9] {
    intrinsics_vec(m)
}
