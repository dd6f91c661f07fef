//! Tube poses from the mounted tag pair on rendered scenes, against the exact poses, with the
//! paper's camera (5472x3648, 77 degrees, default rig distortion) at 1 m and 2 m height.

use nalgebra::{Matrix3, Point3, Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tubeloc_calib::{estimate_tube_pose, CalibError, DetectorConfig, TagDetector, TagMount};
use tubeloc_core::{CameraModel, Pose};
use tubeloc_synth::calib_set::{default_rig, render_planes, BoardLayout};
use tubeloc_synth::tags::TagFamily;

struct Shot {
    model: CameraModel,
    t_cam_tube: Pose,
    image: tubeloc_core::Plane<u8>,
}

/// A tube lying on the ground, the mount's tags rendered (optionally only some ids), seen from
/// a camera at `height` on a 1.8 m circle; the image is cropped around the tags.
fn shot(rng: &mut ChaCha8Rng, mount: &TagMount, height: f64, ids: &[u32]) -> Shot {
    let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let z = Vector3::new(a.cos(), a.sin(), 0.0);
    let y = Vector3::new(0.0, 0.0, -1.0);
    let t_world_tube = Pose::from_parts(Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[y.cross(&z), y, z])), Vector3::new(0.0, 0.0, 0.0085));
    let az: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let eye = Point3::new(1.8 * az.cos(), 1.8 * az.sin(), height);
    let t_world_cam = Pose::look_at(&eye, &Point3::new(0.1, 0.0, 0.0), &Vector3::z()).unwrap();
    let t_cam_tube = t_world_cam.inverse() * t_world_tube;
    let full = default_rig().cameras[1].model.clone();
    let boards: Vec<(Pose, BoardLayout)> = mount.tags.iter().filter(|t| ids.contains(&t.id)).map(|t| (t_cam_tube * t.t_tube_tag, BoardLayout::grid(TagFamily::Tag36h11, 1, 1, t.size_m, t.size_m * 1.6, t.id))).collect();
    // Crop around all mount tags (visible or not) with a margin.
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for t in &mount.tags {
        for c in t.corners_tube() {
            let q = full.project(&t_cam_tube.transform_point(&c)).unwrap();
            x0 = x0.min(q.x);
            y0 = y0.min(q.y);
            x1 = x1.max(q.x);
            y1 = y1.max(q.y);
        }
    }
    let (cx0, cy0) = ((x0 - 60.0).max(0.0) as u32, (y0 - 60.0).max(0.0) as u32);
    let model = full.cropped(cx0, cy0, (x1 + 60.0) as u32 - cx0, (y1 + 60.0) as u32 - cy0);
    let planes: Vec<(Pose, &BoardLayout)> = boards.iter().map(|(p, b)| (*p, b)).collect();
    let image = render_planes(&model, &planes, 2.0, rng.random()).unwrap();
    Shot { model, t_cam_tube, image }
}

fn errors(est: &Pose, truth: &Pose) -> (f64, f64) {
    let pos = (est.translation() - truth.translation()).norm();
    let ax = est.transform_vector(&Vector3::z()).dot(&truth.transform_vector(&Vector3::z())).clamp(-1.0, 1.0).acos();
    (pos, ax.to_degrees())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn tag_pair_poses_at_one_and_two_metres() {
    let mount = TagMount::default_mount();
    let mut det = TagDetector::new(DetectorConfig::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(2021);
    for height in [1.0, 2.0] {
        let (mut pe, mut ae) = (Vec::new(), Vec::new());
        for _ in 0..10 {
            let s = shot(&mut rng, &mount, height, &[0, 1]);
            let dets = det.detect(&s.image).unwrap();
            let est = estimate_tube_pose(&s.model, &mount, &dets).unwrap();
            assert_eq!(est.tags_used, vec![0, 1]);
            assert!(!est.single_tag && !est.ambiguous && est.rms_px < 1.0, "{est:?}");
            assert!(est.covariance[3][3] > 0.0 && est.covariance[0][0] > 0.0);
            let (p, a) = errors(&est.t_cam_tube, &s.t_cam_tube);
            pe.push(p);
            ae.push(a);
        }
        let (mp, ma) = (median(pe.clone()), median(ae.clone()));
        eprintln!("height {height} m: median position error {:.2} mm, median axis angle error {ma:.3} deg (max {:.2} mm, {:.3} deg)", mp * 1e3, pe.iter().fold(0.0f64, |a, b| a.max(*b)) * 1e3, ae.iter().fold(0.0f64, |a, b| a.max(*b)));
        assert!(mp < 0.01 && ma < 1.0, "height {height}: {mp} m, {ma} deg");
    }
}

#[test]
fn one_tag_is_flagged_and_no_tag_is_an_error() {
    let mount = TagMount::default_mount();
    let mut det = TagDetector::new(DetectorConfig::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let s = shot(&mut rng, &mount, 1.0, &[1]);
    let dets = det.detect(&s.image).unwrap();
    let est = estimate_tube_pose(&s.model, &mount, &dets).unwrap();
    assert!(est.single_tag && est.tags_used == vec![1]);
    let (p, _) = errors(&est.t_cam_tube, &s.t_cam_tube);
    // The single tag still gives the position to within a few centimetres.
    assert!(p < 0.05, "single tag position error {p}");
    let s = shot(&mut rng, &mount, 1.0, &[]);
    let dets = det.detect(&s.image).unwrap();
    let e = estimate_tube_pose(&s.model, &mount, &dets).unwrap_err();
    assert!(matches!(e, CalibError::NoTags(_)) && e.to_string().contains("[0, 1]"), "{e}");
}

#[test]
fn shipped_mount_parses_and_bad_mounts_name_the_field() {
    let m = TagMount::default_mount();
    assert_eq!(m.tags.len(), 2);
    assert!((m.tags[0].t_tube_tag.translation() - m.tags[1].t_tube_tag.translation()).norm() > 0.1);
    let bad = tubeloc_calib::mount::DEFAULT_MOUNT_TOML.replacen("size_m = 0.064", "size_m = -1", 1);
    let e = TagMount::from_toml(&bad, std::path::Path::new("m.toml")).unwrap_err().to_string();
    assert!(e.contains("m.toml") && e.contains("tags[0].size_m"), "{e}");
    let bad = tubeloc_calib::mount::DEFAULT_MOUNT_TOML.replacen("[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]", "[0.0, 2.0, 0.0], [0.0, 0.0, 1.0]", 1);
    let e = TagMount::from_toml(&bad, std::path::Path::new("m.toml")).unwrap_err().to_string();
    assert!(e.contains("tags[0].rotation"), "{e}");
}
