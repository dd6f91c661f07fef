//! Pose metrics on hand-built poses with known answers.

use nalgebra::{Point3, Rotation3, Vector3};
use tubeloc_core::{CameraModel, Pose, TubeModel};
use tubeloc_eval::pose::{axis_error, pose_axis_error, AxisLine};
use tubeloc_eval::pose_bop::{average_recall, bop_recalls, mspd, mssd, mssd_thresholds, ModelPoints, Symmetries};

fn gt() -> Pose {
    // A tube lying 1.2 m in front of the camera, axis tilted in the image.
    Pose::from_parts(Rotation3::from_euler_angles(1.1, 0.3, -0.4), Vector3::new(0.05, -0.02, 1.2))
}

fn model() -> ModelPoints {
    ModelPoints::from_tube(&TubeModel::default(), 0.003).unwrap()
}

fn camera() -> CameraModel {
    CameraModel::from_hfov(1280, 960, 60.0)
}

fn rot(axis: Vector3<f64>, deg: f64) -> Pose {
    Pose::from_parts(Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), deg.to_radians()), Vector3::zeros())
}

#[test]
fn rotation_about_the_axis_has_zero_error_in_every_symmetric_metric() {
    let (m, cam) = (model(), camera());
    let axial = Symmetries::tube(1.0, false).unwrap();
    let flip = Symmetries::tube(1.0, true).unwrap();
    for deg in [37.0, 180.0, 271.0] {
        let est = gt() * rot(Vector3::z(), deg);
        let e = pose_axis_error(&est, &gt());
        assert!(e.axis_angle_deg < 1e-6 && e.perpendicular_mm < 1e-9 && e.along_axis_mm.abs() < 1e-9, "{e:?}");
        assert!(e.end_correct);
        assert!(mssd(&est, &gt(), &m, &axial) < 1e-9);
        assert!(mssd(&est, &gt(), &m, &flip) < 1e-9);
        assert!(mspd(&est, &gt(), &m, &axial, &cam) < 1e-6);
        // Without symmetry the same pose is far off: the metric does see rotations.
        assert!(mssd(&est, &gt(), &m, &Symmetries::none()) > 0.005);
    }
}

#[test]
fn flip_is_free_for_the_axis_but_ends_are_wrong() {
    let (m, cam) = (model(), camera());
    let est = gt() * rot(Vector3::x(), 180.0);
    let e = pose_axis_error(&est, &gt());
    assert!(e.axis_angle_deg < 1e-6, "{e:?}");
    assert!(!e.end_correct);
    let flip = Symmetries::tube(2.0, true).unwrap();
    let axial = Symmetries::tube(2.0, false).unwrap();
    assert!(mssd(&est, &gt(), &m, &flip) < 1e-9);
    assert!(mspd(&est, &gt(), &m, &flip, &cam) < 1e-6);
    // Without the flip the ends swap places: the foot rim lands near the seal end, ~150 mm away.
    let no_flip = mssd(&est, &gt(), &m, &axial);
    assert!(no_flip > 0.14 && no_flip < 0.16, "{no_flip}");
    assert!(mspd(&est, &gt(), &m, &axial, &cam) > 50.0);
}

#[test]
fn known_offsets_give_known_distances() {
    let g = AxisLine::new(Point3::new(0.1, 0.2, 1.0), Vector3::new(0.0, 0.0, 2.0)).unwrap();
    // 3 mm along the axis and 4 mm across it.
    let est = AxisLine::new(Point3::new(0.104, 0.2, 1.003), Vector3::new(0.0, 0.0, -1.0)).unwrap();
    let e = axis_error(&est, &g);
    assert!((e.along_axis_mm - 3.0).abs() < 1e-9 && (e.perpendicular_mm - 4.0).abs() < 1e-9, "{e:?}");
    assert!((e.centre_distance_mm - 5.0).abs() < 1e-9);
    assert!(e.axis_angle_deg < 1e-9 && !e.end_correct);
    // A 10° tilt, and 170° (the same line, other end).
    for (deg, end) in [(10.0, true), (170.0, false)] {
        let est = gt() * rot(Vector3::x(), deg);
        let e = pose_axis_error(&est, &gt());
        assert!((e.axis_angle_deg - 10.0).abs() < 1e-9, "{deg}: {e:?}");
        assert_eq!(e.end_correct, end);
    }
    assert!(AxisLine::new(Point3::origin(), Vector3::zeros()).is_err());
    assert!(AxisLine::new(Point3::new(f64::NAN, 0.0, 0.0), Vector3::z()).is_err());
}

#[test]
fn mssd_of_a_translation_equals_its_length() {
    let m = model();
    let shift = Pose::from_parts(Rotation3::identity(), Vector3::new(0.001, -0.002, 0.002));
    let est = shift * gt();
    for sym in [Symmetries::tube(1.0, false).unwrap(), Symmetries::tube(1.0, true).unwrap()] {
        let e = mssd(&est, &gt(), &m, &sym);
        assert!((e - 0.003).abs() < 1e-12, "{e}");
    }
}

#[test]
fn tube_model_points_have_the_tube_diameter() {
    let t = TubeModel::default();
    let m = ModelPoints::from_tube(&t, 0.002).unwrap();
    // Foot rim to the opposite side of the seal rim: sqrt(L² + (r_foot + r_seal)²).
    let want = (0.150f64.powi(2) + (0.0103f64 + 0.0115).powi(2)).sqrt();
    assert!((m.diameter - want).abs() < 2e-4, "{} vs {want}", m.diameter);
    assert!(m.points.iter().all(|p| p.z.abs() <= 0.075 + 1e-12 && (p.x.hypot(p.y) <= 0.0115 + 1e-12)));
    assert!(ModelPoints::from_tube(&t, 0.0).is_err());
    assert!(ModelPoints::from_points(vec![]).is_err());
    assert!(Symmetries::tube(0.0, false).is_err());
    assert_eq!(Symmetries::tube(1.0, true).unwrap().rotations.len(), 720);
}

#[test]
fn recalls_count_unmatched_truths_as_misses() {
    let thr = mssd_thresholds(100.0); // 5, 10, ..., 50
    assert!((thr[0] - 5.0).abs() < 1e-12 && (thr[9] - 50.0).abs() < 1e-12);
    // Errors 0 and 12 for two matched pairs out of four truths.
    let r = bop_recalls(&[0.0, 12.0], 4, &thr);
    assert_eq!(r, vec![0.25, 0.25, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5]);
    assert!((average_recall(&[0.0, 12.0], 4, &thr) - 0.45).abs() < 1e-12);
    // A threshold is strict: an error equal to it is a miss.
    assert_eq!(bop_recalls(&[5.0], 1, &[5.0]), vec![0.0]);
    assert_eq!(bop_recalls(&[], 0, &[5.0]), vec![0.0]);
}
