//! Ground truth agrees with independent geometry: projected silhouettes, poses and boxes.

use nalgebra::{Point2, Point3, Rotation3, Vector3};
use tubeloc_core::{CameraModel, Pose, TubeModel};
use tubeloc_synth::objects::Objects;
use tubeloc_synth::rock::Rock;
use tubeloc_synth::single::{single_tube_scene, Ground};
use tubeloc_synth::{render, tube_truth, Occlusion, RenderOptions, Sun};

fn quiet() -> RenderOptions {
    RenderOptions { sensor: tubeloc_synth::SensorOptions { blur_sigma_px: 0.0, full_well_e: 0.0, read_noise_e: 0.0 }, ..Default::default() }
}

/// Convex hull (monotone chain) of 2D points.
fn hull(mut p: Vec<Point2<f64>>) -> Vec<Point2<f64>> {
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    let cross = |o: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>| (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
    let mut lower: Vec<Point2<f64>> = Vec::new();
    for q in &p {
        while lower.len() >= 2 && cross(&lower[lower.len() - 2], &lower[lower.len() - 1], q) <= 0.0 {
            lower.pop();
        }
        lower.push(*q);
    }
    let mut upper: Vec<Point2<f64>> = Vec::new();
    for q in p.iter().rev() {
        while upper.len() >= 2 && cross(&upper[upper.len() - 2], &upper[upper.len() - 1], q) <= 0.0 {
            upper.pop();
        }
        upper.push(*q);
    }
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

fn inside(poly: &[Point2<f64>], x: f64, y: f64) -> bool {
    let n = poly.len();
    (0..n).all(|i| {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        (b.x - a.x) * (y - a.y) - (b.y - a.y) * (x - a.x) >= 0.0
    })
}

/// Silhouette of the parametric tube as the union of each section's convex hull of its two
/// projected cap circles (exact for a pinhole camera), rasterized at pixel centres.
fn analytic_silhouette(cam: &CameraModel, t_cam_tube: &Pose) -> Vec<bool> {
    let model = TubeModel::default();
    let hulls: Vec<Vec<Point2<f64>>> = model
        .sections
        .iter()
        .map(|s| {
            let (z0, z1) = model.section_z_in_tube_frame(s);
            let mut pts = Vec::new();
            for z in [z0, z1] {
                for k in 0..720 {
                    let a = k as f64 / 720.0 * std::f64::consts::TAU;
                    let p = t_cam_tube.transform_point(&Point3::new(s.radius * a.cos(), s.radius * a.sin(), z));
                    pts.push(cam.project(&p).unwrap());
                }
            }
            hull(pts)
        })
        .collect();
    let (w, h) = (cam.width as usize, cam.height as usize);
    (0..w * h).map(|k| hulls.iter().any(|p| inside(p, (k % w) as f64, (k / w) as f64))).collect()
}

#[test]
fn unoccluded_tube_mask_matches_the_projected_silhouette() {
    let cam = CameraModel::from_hfov(640, 480, 50.0);
    let sun = Sun { elevation_deg: 55.0, azimuth_deg: 120.0 };
    for (k, (yaw, dist, tilt)) in [(0.3f64, 0.45f64, 0.9f64), (1.2, 0.6, 0.6), (-0.7, 0.4, 1.1)].into_iter().enumerate() {
        // Tube axis horizontal in a ground tilted toward the camera by `tilt` (radians).
        let r = Rotation3::from_axis_angle(&Vector3::x_axis(), -tilt) * Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2 + yaw);
        let t_cam_tube = Pose::from_parts(r, Vector3::new(0.02 * k as f64, 0.01, dist));
        let (scene, t_world_cam) = single_tube_scene(&t_cam_tube, Ground::Textured, sun, 3).unwrap();
        let out = render(&scene, &cam, &t_world_cam, &quiet());
        let truth = tube_truth(&scene.objects, &cam, &t_world_cam, &out);
        assert_eq!(truth.len(), 1);
        let t = &truth[0];
        let (_, dt) = t.t_cam_tube.distance(&t_cam_tube);
        assert!(dt < 1e-9, "T_cam_tube mismatch {dt}");
        let sil = analytic_silhouette(&cam, &t_cam_tube);
        let area_sil = sil.iter().filter(|&&b| b).count() as f64;
        let inter = sil.iter().zip(&t.visible.data).filter(|(a, b)| **a && **b != 0).count() as f64;
        let union = area_sil + t.visible_area as f64 - inter;
        assert!(area_sil > 800.0, "silhouette too small to test: {area_sil}");
        let rel = (t.visible_area as f64 - area_sil).abs() / area_sil;
        assert!(rel < 0.02, "case {k}: mask area {} vs silhouette {area_sil}", t.visible_area);
        assert!(inter / union > 0.97, "case {k}: IoU {}", inter / union);
        assert!(t.visible_fraction > 0.97 && t.occlusion == Occlusion::None, "case {k}: {} {:?}", t.visible_fraction, t.occlusion);
        assert!((t.amodal_area as f64 - area_sil).abs() / area_sil < 0.02);
        // Projected axis end points and centre fall in the box.
        let [x, y, w, h] = t.bbox;
        for z in [-0.074, 0.0, 0.074] {
            let p = cam.project(&t_cam_tube.transform_point(&Point3::new(0.0, 0.0, z))).unwrap();
            assert!(p.x >= x - 0.5 && p.x <= x + w - 0.5 && p.y >= y - 0.5 && p.y <= y + h - 0.5, "case {k}: {p:?} outside {:?}", t.bbox);
        }
        // Depth at the tube's centre pixel equals the camera-z of the surface seen there.
        let c = cam.project(&Point3::from(t_cam_tube.translation())).unwrap();
        let (cu, cv) = (c.x.round() as usize, c.y.round() as usize);
        let d = out.depth.get(cu, cv) as f64;
        assert_eq!(out.instance.get(cu, cv), 1, "case {k}: centre pixel {c:?} not on the tube");
        // The ray meets the surface before the axis, within r / sin(angle to the axis).
        assert!(d < t_cam_tube.translation().z && d > t_cam_tube.translation().z - 0.04, "case {k}: depth {d}");
    }
}

#[test]
fn a_rock_in_front_hides_part_of_the_tube_and_is_named() {
    let cam = CameraModel::from_hfov(480, 360, 50.0);
    let r = Rotation3::from_axis_angle(&Vector3::x_axis(), -0.8) * Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
    let t_cam_tube = Pose::from_parts(r, Vector3::new(0.0, 0.0, 0.6));
    let (mut scene, t_world_cam) = single_tube_scene(&t_cam_tube, Ground::Plain, Sun { elevation_deg: 60.0, azimuth_deg: 200.0 }, 1).unwrap();
    let before = {
        let out = render(&scene, &cam, &t_world_cam, &quiet());
        tube_truth(&scene.objects, &cam, &t_world_cam, &out)[0].clone()
    };
    // A rock on the ground between the camera and one end of the tube.
    let cam_pos = t_world_cam.translation();
    let end = scene.objects.tubes[0].t_world_tube.transform_point(&Point3::new(0.0, 0.0, 0.05));
    // On the line of sight to that end, 8 cm in front of it (floating: only visibility matters).
    let c = end + (Point3::from(cam_pos) - end).normalize() * 0.08;
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(2);
    let rock = Rock::new(&mut rng, c, [0.03, 0.03, 0.03], 0.0, 0.0, 24, [0.1; 3]);
    let tubes = scene.objects.tubes.clone();
    scene.objects = Objects::new(vec![rock], tubes, Vec::new());
    scene.objects.build_grid(-3.0, -3.0, 0.1, 60, 60);
    let out = render(&scene, &cam, &t_world_cam, &quiet());
    let t = &tube_truth(&scene.objects, &cam, &t_world_cam, &out)[0];
    assert_eq!(t.occlusion, Occlusion::Rock);
    assert!(t.visible_fraction < 0.95 && t.visible_fraction > 0.2, "fraction {}", t.visible_fraction);
    assert!((t.amodal_area as i64 - before.amodal_area as i64).abs() <= 2, "amodal area must not depend on occluders");
    assert!(t.visible_area < before.visible_area);
}

#[test]
fn tube_partly_outside_the_image_is_a_border_case() {
    let cam = CameraModel::from_hfov(320, 240, 50.0);
    let r = Rotation3::from_axis_angle(&Vector3::x_axis(), -0.8) * Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
    // Tube centre near the left edge.
    let z = 0.5;
    let x_edge = (0.0 - cam.cx) / cam.fx * z;
    let t_cam_tube = Pose::from_parts(r, Vector3::new(x_edge + 0.02, 0.0, z));
    let (scene, t_world_cam) = single_tube_scene(&t_cam_tube, Ground::Plain, Sun { elevation_deg: 60.0, azimuth_deg: 200.0 }, 1).unwrap();
    let out = render(&scene, &cam, &t_world_cam, &quiet());
    let t = &tube_truth(&scene.objects, &cam, &t_world_cam, &out)[0];
    assert_eq!(t.occlusion, Occlusion::Border);
    assert!(t.visible_fraction > 0.2 && t.visible_fraction < 0.9, "{}", t.visible_fraction);
    assert!(t.amodal_bbox[0] < 0.0 && t.bbox[0] == 0.0);
}
