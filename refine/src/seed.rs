//! Initial poses for the fit from the different detectors.
//!
//! - Line2D: the template pose `T_cam_tube` gives centre and axis directly (end known, but
//!   template flips happen, so the end is re-decided from the image).
//! - Learned mask / axis seed (or the box alone): the axis is the image line through
//!   `centre_px` along `direction_px`; its 3D placement comes from, in order of preference,
//!   stereo points (median depth of the region plus the radius), a ground plane (the axis lies
//!   `max_radius` above it), or the tube's known size (`Z = f · 2 r_max / width_px` for masks,
//!   `Z = f · L / length_px` for boxes). The axis lies in the plane through the camera centre
//!   and the image line, parallel to the ground plane when there is one, else perpendicular to
//!   the viewing ray. Stereo depth wins over the ground's: the plane is the rig's nominal
//!   ground, and terrain relief of a few centimetres would put the seed under the measured
//!   surface, where the scene-occlusion test hides its whole contour.

use crate::contour::AxisState;
use crate::error::RefineError;
use crate::model::CylinderModel;
use nalgebra::{Point2, Point3, Vector3};
use tubeloc_core::{CameraModel, Pose, TubeDetection};

/// A template pose's image axis as an axis seed ([`tubeloc_core::AxisSeed`], as a learned mask's
/// axis), the detection otherwise unchanged and without its pose: `centre_px` the projected
/// centre, `direction_px` the image direction from the foot end `c - a L/2` to the seal end
/// `c + a L/2` (so the template's end claim stays in the direction's sign), `length_px` their
/// image distance and `width_px = f · 2 r_body / Z`. `None` when the detection has no template
/// pose, a point does not project, or the tube is seen end-on (under a pixel long).
///
/// With a ground plane the refiner places such a seed on the ground ([`seed_from_detection`]),
/// which beats the template's own distance and tilt (those of the nearest template view; see
/// [`crate::settings::SeedProfiles::template_as_image_axis`]).
pub fn template_image_axis(det: &TubeDetection, camera: &CameraModel, model: &CylinderModel) -> Option<TubeDetection> {
    let AxisState { c, a } = axis_state_of(det.t_cam_tube.as_ref()?);
    let a = a.normalize();
    let [u, u0, u1] = [c, c - a * (0.5 * model.length), c + a * (0.5 * model.length)].map(|x| camera.project(&Point3::from(x)));
    let (u, u0, u1) = (u?, u0?, u1?);
    let d = u1 - u0;
    let length_px = d.norm();
    if !(length_px >= 1.0 && c.z > 0.0) {
        return None;
    }
    let width_px = 0.5 * (camera.fx + camera.fy) * 2.0 * model.body_radius() / c.z;
    let axis_seed = tubeloc_core::AxisSeed { centre_px: [u.x, u.y], direction_px: [d.x / length_px, d.y / length_px], length_px, width_px };
    Some(TubeDetection { t_cam_tube: None, axis_seed: Some(axis_seed), ..det.clone() })
}

/// The ground plane in the camera frame (`normal · X = offset`, normal up, metres); defined in
/// `tubeloc-core` so that every crate and command shares one sign convention.
pub use tubeloc_core::GroundPlane;

/// A seed for the fit: pose parameters and whether the axis sign is known to point at the seal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seed {
    /// Centre and axis.
    pub state: AxisState,
    /// True when `state.a` points toward the seal end by the detector's claim.
    pub end_known: bool,
}

/// A seed `pos_m` / `ang_deg` away from a known pose, for measuring the basin of the fit:
/// the centre moved by a uniform random offset in `[-pos_m, pos_m]` per camera coordinate and
/// the axis turned by exactly `ang_deg` about a random direction perpendicular to it.
/// Deterministic in
/// `seed` (ChaCha8).
pub fn perturbed(state: &AxisState, pos_m: f64, ang_deg: f64, seed: u64) -> AxisState {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let dc = Vector3::new(rng.random_range(-1.0..=1.0), rng.random_range(-1.0..=1.0), rng.random_range(-1.0..=1.0)) * pos_m;
    let dir = loop {
        let v = Vector3::new(rng.random_range(-1.0..=1.0), rng.random_range(-1.0..=1.0), rng.random_range(-1.0..=1.0));
        let v = v - state.a * state.a.dot(&v) / state.a.norm_squared().max(1e-300);
        let n = v.norm();
        if n > 1e-3 {
            break v / n;
        }
    };
    let r = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_unchecked(dir), ang_deg.to_radians());
    AxisState { c: state.c + dc, a: r * state.a }
}

/// A template pose found under camera `from` moved to camera `to` so that it looks the same:
/// its centre is turned about the camera centre from its viewing ray under `from` onto the ray
/// of the same pixel under `to` (the axis turned alike). For detections made with another
/// principal point or focal length than the image's own camera (e.g. a crop). `None` when the
/// centre does not project.
pub fn reanchored(state: &AxisState, from: &CameraModel, to: &CameraModel) -> Option<AxisState> {
    let u = from.project(&Point3::from(state.c))?;
    let new_ray = to.unproject(&u);
    let r = nalgebra::Rotation3::rotation_between(&state.c, &new_ray)?;
    Some(AxisState { c: r * state.c, a: r * state.a })
}

/// The axis state of a tube pose `T_cam_tube`: centre = its translation, axis = its +z (toward
/// the seal end) in the camera frame.
pub fn axis_state_of(t: &Pose) -> AxisState {
    AxisState { c: t.translation(), a: t.transform_vector(&Vector3::z()) }
}

/// [`reanchored`] for a full template pose `T_cam_tube` (camera `from` -> camera `to`): the
/// same rotation about the camera centre applied to the tube's orientation. `None` when the
/// centre does not project; the pose unchanged when the rotation is undefined (opposite rays).
pub fn reanchored_pose(t: &Pose, from: &CameraModel, to: &CameraModel) -> Option<Pose> {
    let st = axis_state_of(t);
    let r = reanchored(&st, from, to)?;
    let rot = nalgebra::Rotation3::rotation_between(&st.c, &r.c).unwrap_or_else(nalgebra::Rotation3::identity);
    Some(Pose::from_parts(nalgebra::Rotation3::from_matrix_unchecked(rot.matrix() * t.rotation()), r.c))
}

/// The mask axis' centre moved along the axis to the foot of the perpendicular from the box
/// centre (`bbox` COCO `[x, y, w, h]`, pixels): `c + d̂ ((b - c)·d̂)`. The learned segmenter's
/// axis centre (the mask centroid) lies toward the wider end sections; the box spans the
/// silhouette's extent: on the paper preset (80 no-tags images) the centre's image error along
/// the axis went 11.2 -> 5.2 px at the median (p90 36.0 -> 19.3), and a ground-plane seed's
/// distance follows it. Unchanged when the box or the direction is degenerate.
pub fn recentred_along_axis(c: &Point2<f64>, d: &nalgebra::Vector2<f64>, bbox: &[f64; 4]) -> Point2<f64> {
    let n = d.norm();
    if !(n > 1e-12 && bbox.iter().all(|v| v.is_finite()) && bbox[2] > 0.0 && bbox[3] > 0.0) {
        return *c;
    }
    let u = d / n;
    let b = Point2::new(bbox[0] + 0.5 * bbox[2], bbox[1] + 0.5 * bbox[3]);
    c + u * (b - c).dot(&u)
}

/// Builds a seed from a detection. See the module docs for the order of preference.
pub fn seed_from_detection(det: &TubeDetection, camera: &CameraModel, model: &CylinderModel, ground: Option<&GroundPlane>, stereo: &[Point3<f64>]) -> Result<Seed, RefineError> {
    if let Some(t) = &det.t_cam_tube {
        let c = t.translation();
        let a = t.transform_vector(&Vector3::z());
        if c.iter().any(|v| !v.is_finite()) || c.z <= 0.0 {
            return Err(RefineError::Seed(format!("template pose places the tube behind the camera (z = {:.3} m)", c.z)));
        }
        return Ok(Seed { state: AxisState { c, a: a.normalize() }, end_known: true });
    }
    let from_mask = det.axis_seed.is_some();
    let ax = det.axis_seed.unwrap_or_else(|| det.axis_seed_from_bbox());
    ax.validate().map_err(|e| RefineError::Seed(e.to_string()))?;
    let d_px = nalgebra::Vector2::new(ax.direction_px[0], ax.direction_px[1]);
    let c_px = if from_mask { recentred_along_axis(&Point2::new(ax.centre_px[0], ax.centre_px[1]), &d_px, &det.bbox) } else { Point2::new(ax.centre_px[0], ax.centre_px[1]) };
    let r0 = camera.unproject(&c_px);
    let r1 = camera.unproject(&(c_px + d_px * (0.25 * ax.length_px).max(5.0)));
    let m = r0.cross(&r1);
    if m.norm() < 1e-12 {
        return Err(RefineError::Seed("axis seed has zero image length".into()));
    }
    let m = m.normalize();
    let f = 0.5 * (camera.fx + camera.fy);
    // Axis direction: parallel to the ground plane when there is one (inside the plane through
    // the camera centre and the image line), else perpendicular to the viewing ray.
    let ground_axis = ground.map(|g| (g, m.cross(&g.normal))).filter(|(_, a)| a.norm() > 1e-3);
    let axis = ground_axis.map_or_else(|| r0.cross(&m).normalize(), |(_, a)| a.normalize());
    let mut state = None;
    if !stereo.is_empty() {
        let mut z: Vec<f64> = stereo.iter().map(|p| p.z).filter(|z| z.is_finite() && *z > 0.0).collect();
        if !z.is_empty() {
            let mid = z.len() / 2;
            let (_, zm, _) = z.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
            let zc = *zm + model.body_radius();
            state = Some(AxisState { c: r0 * (zc / r0.z), a: axis });
        }
    }
    if let (None, Some((g, _))) = (state, ground_axis) {
        let den = g.normal.dot(&r0);
        if den.abs() > 1e-6 {
            let t = (g.offset + model.max_radius()) / den;
            if t > 0.0 {
                state = Some(AxisState { c: r0 * t, a: axis });
            }
        }
    }
    let mut state = match state {
        Some(s) => s,
        None => {
            let z = if from_mask { f * 2.0 * model.max_radius() / ax.width_px } else { f * (model.length + 2.0 * model.max_radius()) / ax.length_px };
            if !(z.is_finite() && z > 0.0) {
                return Err(RefineError::Seed(format!("cannot infer depth from the seed (width {} px, length {} px)", ax.width_px, ax.length_px)));
            }
            AxisState { c: r0 * (z / r0.z), a: r0.cross(&m).normalize() }
        }
    };
    // Orient the axis along the image direction of the seed.
    if let (Some(p0), Some(p1)) = (camera.project(&Point3::from(state.c)), camera.project(&Point3::from(state.c + state.a * 0.01))) {
        if (p1 - p0).dot(&d_px) < 0.0 {
            state.a = -state.a;
        }
    }
    Ok(Seed { state, end_known: false })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn template_image_axis_keeps_the_pixel_the_seal_end_and_the_size() {
        let cam = CameraModel::from_hfov(1024, 1024, 40.0);
        let model = CylinderModel::new(&tubeloc_core::TubeModel::default()).unwrap();
        let (c, a) = (Vector3::new(0.1, 0.2, 2.0), Vector3::new(1.0, 0.2, -0.3).normalize());
        let rot = nalgebra::Rotation3::rotation_between(&Vector3::z(), &a).unwrap();
        let mut det = TubeDetection::new(3, 0.8, [500.0, 500.0, 40.0, 20.0], tubeloc_core::DetectionSource::Line2d);
        det.t_cam_tube = Some(Pose::from_parts(rot, c));
        let ax = template_image_axis(&det, &cam, &model).unwrap();
        assert!(ax.t_cam_tube.is_none() && ax.bbox == det.bbox && ax.image_id == 3);
        let s = ax.axis_seed.unwrap();
        let u = cam.project(&Point3::from(c)).unwrap();
        assert!((s.centre_px[0] - u.x).abs() < 1e-9 && (s.centre_px[1] - u.y).abs() < 1e-9);
        // Toward the seal end (+a), and as long as the projected tube.
        let seal = cam.project(&Point3::from(c + a * 0.05)).unwrap() - u;
        assert!(seal.x * s.direction_px[0] + seal.y * s.direction_px[1] > 0.0);
        let ends = cam.project(&Point3::from(c + a * (0.5 * model.length))).unwrap() - cam.project(&Point3::from(c - a * (0.5 * model.length))).unwrap();
        assert!((s.length_px - ends.norm()).abs() < 1e-9);
        assert!((s.width_px - cam.fx * 2.0 * model.body_radius() / c.z).abs() < 1e-9);
        // End-on (under a pixel long): no axis; no template pose: no axis.
        det.t_cam_tube = Some(Pose::from_parts(nalgebra::Rotation3::rotation_between(&Vector3::z(), &c.normalize()).unwrap(), c));
        assert!(template_image_axis(&det, &cam, &model).is_none());
        det.t_cam_tube = None;
        assert!(template_image_axis(&det, &cam, &model).is_none());
    }

    #[test]
    fn reanchored_pose_projects_to_the_same_pixel_at_the_same_distance() {
        let from = CameraModel::from_hfov(1024, 1024, 40.0);
        let mut to = from.clone();
        to.cx = -237.5;
        to.cy = 776.5;
        let st = AxisState { c: Vector3::new(0.2, -0.1, 2.5), a: Vector3::new(1.0, 0.3, 0.1).normalize() };
        let r = reanchored(&st, &from, &to).unwrap();
        let (u0, u1) = (from.project(&Point3::from(st.c)).unwrap(), to.project(&Point3::from(r.c)).unwrap());
        assert!((u0 - u1).norm() < 1e-9, "{u0} vs {u1}");
        assert!((r.c.norm() - st.c.norm()).abs() < 1e-12);
        // The axis keeps its angle to the viewing ray.
        assert!((r.a.dot(&r.c.normalize()) - st.a.dot(&st.c.normalize())).abs() < 1e-12);
    }

    #[test]
    fn reanchored_full_pose_turns_the_orientation_with_the_axis() {
        let from = CameraModel::from_hfov(1024, 1024, 40.0);
        let mut to = from.clone();
        to.cx = -237.5;
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 1.1);
        let t = Pose::from_parts(rot, Vector3::new(0.2, -0.1, 2.5));
        let p = reanchored_pose(&t, &from, &to).unwrap();
        let (st, r) = (axis_state_of(&p), reanchored(&axis_state_of(&t), &from, &to).unwrap());
        assert!((st.c - r.c).norm() < 1e-12 && (st.a - r.a).norm() < 1e-12);
        // A rotation: the tube's x axis stays perpendicular to its axis.
        assert!(p.transform_vector(&Vector3::x()).dot(&st.a).abs() < 1e-12);
    }

    #[test]
    fn mask_seed_takes_its_depth_from_stereo_and_its_tilt_from_the_ground() {
        // Camera 1 m above the nominal ground, pitched down 45 degrees; the tube lies on a dune
        // 5 cm above that ground, along the camera's x axis.
        let cam = CameraModel::from_hfov(640, 480, 60.0);
        let model = CylinderModel::plain(0.15, 0.01).unwrap();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let up = Vector3::new(0.0, -h, -h);
        let ground = GroundPlane::from_point_normal(&(-up), &up);
        let r0 = cam.unproject(&Point2::new(320.0, 300.0));
        let t = (ground.offset + 0.05 + model.max_radius()) / up.dot(&r0);
        let (centre, axis) = (r0 * t, Vector3::x());
        let (p0, p1) = (cam.project(&Point3::from(centre - axis * 0.075)).unwrap(), cam.project(&Point3::from(centre + axis * 0.075)).unwrap());
        let mut det = TubeDetection::new(1, 0.9, [p0.x, 300.0 - 5.0, p1.x - p0.x, 10.0], tubeloc_core::DetectionSource::Learned);
        det.axis_seed = Some(tubeloc_core::AxisSeed { centre_px: [320.0, 300.0], direction_px: [1.0, 0.0], length_px: p1.x - p0.x, width_px: 10.0 });
        // Stereo points on the tube's near surface along the viewing ray of its centre.
        let near = centre.z - model.body_radius();
        let stereo: Vec<Point3<f64>> = (0..9).map(|k| Point3::new(-0.04 + 0.01 * k as f64, centre.y, near)).collect();
        let seed = seed_from_detection(&det, &cam, &model, Some(&ground), &stereo).unwrap();
        assert!((seed.state.c - centre).norm() < 1e-3, "stereo depth: centre off by {:.4} m", (seed.state.c - centre).norm());
        assert!(seed.state.a.dot(&up).abs() < 1e-9 && seed.state.a.x.abs() > 1.0 - 1e-9, "ground tilt: axis {}", seed.state.a);
        // The ground alone puts the seed on the nominal plane, 5 cm below the dune, along the ray.
        let seed = seed_from_detection(&det, &cam, &model, Some(&ground), &[]).unwrap();
        assert!((up.dot(&seed.state.c) - (ground.offset + model.max_radius())).abs() < 1e-9);
        assert!((seed.state.c - centre).norm() > 0.05);
    }

    #[test]
    fn mask_centre_is_moved_along_the_axis_onto_the_box_centre() {
        let d = nalgebra::Vector2::new(3.0, 4.0);
        // Box centre (110, 60); the centre (100, 50) moves along (0.6, 0.8) by 14 px.
        let c = recentred_along_axis(&Point2::new(100.0, 50.0), &d, &[90.0, 40.0, 40.0, 40.0]);
        assert!((c - Point2::new(108.4, 61.2)).norm() < 1e-9, "{c}");
        // Off-axis displacement of the box is ignored: the axis line is kept.
        let c = recentred_along_axis(&Point2::new(100.0, 50.0), &d, &[72.0, 36.0, 40.0, 40.0]);
        assert!((c - Point2::new(100.0, 50.0)).norm() < 1e-9, "{c}");
        // Degenerate boxes leave the centre alone.
        assert_eq!(recentred_along_axis(&Point2::new(1.0, 2.0), &d, &[0.0, 0.0, 0.0, 5.0]), Point2::new(1.0, 2.0));
        assert_eq!(recentred_along_axis(&Point2::new(1.0, 2.0), &d, &[f64::NAN, 0.0, 4.0, 5.0]), Point2::new(1.0, 2.0));
    }

    #[test]
    fn perturbation_has_the_requested_size_and_is_reproducible() {
        let st = AxisState { c: Vector3::new(0.1, 0.2, 1.5), a: Vector3::new(1.0, 0.5, -0.2).normalize() };
        for k in 0..20 {
            let p = perturbed(&st, 0.01, 5.0, k);
            assert_eq!(p, perturbed(&st, 0.01, 5.0, k));
            let d = p.c - st.c;
            assert!(d.iter().all(|v| v.abs() <= 0.01 + 1e-15), "{d:?}");
            assert!((p.a.dot(&st.a).clamp(-1.0, 1.0).acos().to_degrees() - 5.0).abs() < 1e-9);
        }
        assert_ne!(perturbed(&st, 0.01, 5.0, 1), perturbed(&st, 0.01, 5.0, 2));
    }
}
