//! Rectification geometry, triangulation accuracy in 3D and error cases.

use nalgebra::{Point2, Point3, Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tubeloc_core::{CameraModel, Distortion, Plane, Pose};
use tubeloc_stereo::{StereoError, StereoRectification};

fn cams() -> (CameraModel, CameraModel, Pose) {
    let l = CameraModel { distortion: Distortion { k1: -0.08, k2: 0.02, p1: 0.0005, p2: -0.0003, k3: 0.0 }, ..CameraModel::from_hfov(800, 600, 60.0) };
    let r = CameraModel { fx: l.fx * 1.01, cx: l.cx + 3.0, distortion: Distortion { k1: -0.07, ..l.distortion }, ..l.clone() };
    // Right camera 20 cm to the right, slightly rotated (a real rig is never perfectly parallel).
    let t_left_right = Pose::from_parts(Rotation3::from_euler_angles(0.02, -0.04, 0.01), Vector3::new(0.2, 0.004, -0.006));
    (l, r, t_left_right)
}

fn random_points(n: usize, seed: u64) -> Vec<Point3<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let z = rng.random_range(1.0..6.0);
            Point3::new(rng.random_range(-0.3..0.3) * z, rng.random_range(-0.2..0.2) * z, z)
        })
        .collect()
}

#[test]
fn rectified_rows_align_and_disparity_gives_depth() {
    let (l, r, t_lr) = cams();
    let rect = StereoRectification::new(&l, &r, &t_lr).unwrap();
    let g = rect.geometry();
    let t_rl = t_lr.inverse();
    for p in random_points(200, 1) {
        let pl = Point3::from(rect.r_left * p.coords);
        let pr = Point3::from(rect.r_right * t_rl.transform_point(&p).coords);
        let (ul, ur) = (rect.rectified.project(&pl).unwrap(), rect.rectified.project(&pr).unwrap());
        assert!((ul.y - ur.y).abs() < 1e-9, "rows differ: {} vs {}", ul.y, ur.y);
        let d = ul.x - ur.x;
        assert!((g.depth(d).unwrap() - pl.z).abs() < 1e-9 * pl.z);
        // Triangulation back into the original left camera frame recovers the point.
        let q = g.triangulate_pixel(ul.x, ul.y, d, 0.25).unwrap();
        let back = rect.to_left_camera(&q.point);
        assert!((back - p).norm() < 1e-9, "{back:?} vs {p:?}");
        // Q matrix agrees: (X Y Z W) = Q (u v d 1).
        let h = rect.q * nalgebra::Vector4::new(ul.x, ul.y, d, 1.0);
        assert!((h.z / h.w - pl.z).abs() < 1e-9 * pl.z);
        // P1 and P2 project the rectified point to the rectified pixels.
        let (a, b) = (rect.p1 * pl.to_homogeneous(), rect.p2 * pl.to_homogeneous());
        assert!((a.x / a.z - ul.x).abs() < 1e-9 && (b.x / b.z - ur.x).abs() < 1e-9);
    }
}

#[test]
fn remap_tables_invert_distortion_and_rotation() {
    let (l, r, t_lr) = cams();
    let rect = StereoRectification::new(&l, &r, &t_lr).unwrap();
    let v = rect.valid_left;
    assert!(v.width > 600 && v.height > 450, "valid region too small: {v:?}");
    for (cam, rot, map, valid) in [(&l, rect.r_left, &rect.map_left, v), (&r, rect.r_right, &rect.map_right, rect.valid_right)] {
        for (u, w) in [(valid.x, valid.y), (valid.x + valid.width - 1, valid.y + valid.height - 1), (400, 300), (100, 500)] {
            let (sx, sy) = (map.map_x.get(u, w), map.map_y.get(u, w));
            assert!(!sx.is_nan(), "({u},{w}) inside the valid rectangle has no source");
            let ray = rot * cam.unproject(&Point2::new(sx as f64, sy as f64));
            let back = rect.rectified.project(&Point3::from(ray)).unwrap();
            assert!((back.x - u as f64).abs() < 1e-2 && (back.y - w as f64).abs() < 1e-2, "({u},{w}) -> {back:?}");
        }
    }
    // Bilinear remap of a horizontal ramp reproduces the ramp at the source coordinates.
    let ramp = Plane::from_vec(800, 600, (0..600 * 800).map(|i| ((i % 800) / 4) as u8).collect());
    let (rl, _) = rect.rectify_pair(&ramp, &ramp).unwrap();
    let (sx, _) = (rect.map_left.map_x.get(400, 300), 0);
    assert!((rl.get(400, 300) as f32 - sx / 4.0).abs() <= 1.0);
}

#[test]
fn depth_noise_matches_sigma_z() {
    let (l, r, t_lr) = cams();
    let g = StereoRectification::new(&l, &r, &t_lr).unwrap().geometry();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (d0, sigma_d) = (40.0, 0.3);
    let sigma_z = g.triangulate_pixel(400.0, 300.0, d0, sigma_d).unwrap().sigma_z;
    let zs: Vec<f64> = (0..20000)
        .map(|_| {
            // Box-Muller normal sample.
            let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
            let n = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
            g.depth(d0 + sigma_d * n).unwrap()
        })
        .collect();
    let mean = zs.iter().sum::<f64>() / zs.len() as f64;
    let std = (zs.iter().map(|z| (z - mean).powi(2)).sum::<f64>() / zs.len() as f64).sqrt();
    assert!((std / sigma_z - 1.0).abs() < 0.05, "empirical {std} vs predicted {sigma_z}");
}

#[test]
fn unrectifiable_rigs_and_size_mismatch_are_refused() {
    let (l, r, _) = cams();
    let zero = Pose::identity();
    let e = StereoRectification::new(&l, &r, &zero).unwrap_err();
    assert!(matches!(e, StereoError::Unrectifiable(_)) && e.to_string().contains("zero baseline"), "{e}");
    let forward = Pose::from_parts(Rotation3::identity(), Vector3::new(0.05, 0.0, 0.3));
    let e = StereoRectification::new(&l, &r, &forward).unwrap_err().to_string();
    assert!(e.contains("optical axis"), "{e}");
    let small = CameraModel::from_hfov(640, 480, 60.0);
    let e = StereoRectification::new(&l, &small, &cams().2).unwrap_err().to_string();
    assert!(e.contains("800x600") && e.contains("640x480"), "{e}");
    let rect = StereoRectification::new(&l, &r, &cams().2).unwrap();
    let e = rect.rectify_pair(&Plane::new(800, 600), &Plane::new(800, 599)).unwrap_err().to_string();
    assert!(e.contains("right image") && e.contains("800x599"), "{e}");
}
