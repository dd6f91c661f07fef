//! Grasp checks on small scenes with known answers, parry's distances against brute-force
//! point-in-shape tests, and the gripper file's errors.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::query;
use parry3d_f64::shape::{Cuboid, Cylinder, HalfSpace, Shape};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;
use tubeloc_core::{GroundPlane, TubeAxisPose, TubeModel};
use tubeloc_grasp::{GraspPlanner, GripperModel, PlannerSettings, Scene, Terrain, TerrainSettings, TubeSolid, DEFAULT_GRIPPER_TOML};

/// Level camera 1.5 m above flat ground (camera y down): up is -y, the ground is y = 1.5.
fn ground() -> GroundPlane {
    GroundPlane::new(Vector3::new(0.0, -1.0, 0.0), -1.5).unwrap()
}

/// A default tube lying on the ground (on its 11.5 mm seal section) at camera (x, 1.5 - r, z)
/// along `axis` (toward the seal end), seal end known.
fn tube_on_ground(x: f64, z: f64, axis: Vector3<f64>) -> TubeAxisPose {
    TubeAxisPose::new(0, 0.9, Vector3::new(x, 1.5 - 0.0115, z), axis, 0.9).unwrap()
}

fn planner() -> GraspPlanner {
    GraspPlanner::new(GripperModel::default(), PlannerSettings::default(), &TubeModel::default()).unwrap()
}

/// Points every 2 mm over the square of half side `half` around (x0, z0): on the top of the rock
/// (height `rock_h` over camera x in `rock_x`, all z in `rock_z`), on the ground elsewhere.
fn terrain_points(x0: f64, z0: f64, half: f64, rock_x: (f64, f64), rock_z: (f64, f64), rock_h: f64) -> Vec<Point3<f64>> {
    let n = (2.0 * half / 0.002) as i64;
    let mut pts = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            let (x, z) = (x0 - half + i as f64 * 0.002, z0 - half + j as f64 * 0.002);
            let on_rock = (rock_x.0..=rock_x.1).contains(&x) && (rock_z.0..=rock_z.1).contains(&z);
            pts.push(Point3::new(x, 1.5 - if on_rock { rock_h } else { 0.0 }, z));
        }
    }
    pts
}

#[test]
fn a_rock_over_one_side_moves_the_grasp_to_the_free_side() {
    let p = planner();
    let tube = tube_on_ground(0.0, 1.0, Vector3::x());
    // A 40 mm high rock over the seal end and the body's upper part (camera x from -20 mm on),
    // wider than the gripper across the tube.
    let pts = terrain_points(0.0, 1.0, 0.2, (-0.020, 0.2), (0.9, 1.1), 0.040);
    let terrain = Terrain::from_points(&pts, &ground(), &tube, p.terrain_radius(), std::slice::from_ref(&tube), &TubeModel::default(), &TerrainSettings::default(), 0.0);
    assert!(terrain.column_cells > 0 && terrain.measured_cells > terrain.column_cells, "{terrain:?}");
    let check = p.check(&tube, &ground().normal, &Scene { ground: ground(), tubes: &[], terrain: Some(&terrain) });
    assert!(check.feasible && check.changed && check.terrain_checked, "{check:?}");
    // Tilts of 20 degrees and more put a fingertip into the ground under a lying tube.
    assert!(check.rejected.terrain > 0 && check.rejected.ground > 0 && check.rejected.tube == 0, "{check:?}");
    // The fingers (20 mm wide) stand clear of the rock: their +x edge below x = -20 mm.
    assert!(check.shift_mm + 10.0 < -20.0, "shift {} mm", check.shift_mm);
    let origin = check.t_cam_grasp.translation();
    assert!((origin - (tube.centre + Vector3::x() * check.shift_mm * 1e-3)).norm() < 1e-12);
    // Without the rock the plain grasp stands: clearance is the fingertips' height, 11.5 - 3 mm.
    let flat = terrain_points(0.0, 1.0, 0.2, (0.0, 0.0), (0.0, 0.0), 0.0);
    let terrain = Terrain::from_points(&flat, &ground(), &tube, p.terrain_radius(), std::slice::from_ref(&tube), &TubeModel::default(), &TerrainSettings::default(), 0.0);
    assert_eq!(terrain.column_cells, 0);
    let check = p.check(&tube, &ground().normal, &Scene { ground: ground(), tubes: &[], terrain: Some(&terrain) });
    assert!(check.feasible && !check.changed && check.terrain_checked, "{check:?}");
    assert!((check.clearance_mm - 8.5).abs() < 1e-6, "{check:?}");
    assert_eq!(check.t_cam_grasp, tube.grasp_frame(&ground().normal));
}

#[test]
fn the_tubes_own_points_are_not_terrain() {
    let p = planner();
    let tube = tube_on_ground(0.0, 1.0, Vector3::x());
    // Points on the tube's upper surface (up to 23 mm above the ground) and flat ground around.
    let mut pts = terrain_points(0.0, 1.0, 0.2, (0.0, 0.0), (0.0, 0.0), 0.0);
    for i in 0..75 {
        for k in 0..8 {
            let (x, a) = (-0.074 + i as f64 * 0.002, k as f64 * std::f64::consts::PI / 8.0);
            pts.push(Point3::new(x, tube.centre.y - 0.0105 * a.sin(), 1.0 + 0.0105 * a.cos()));
        }
    }
    let terrain = Terrain::from_points(&pts, &ground(), &tube, p.terrain_radius(), std::slice::from_ref(&tube), &TubeModel::default(), &TerrainSettings::default(), 0.0);
    assert_eq!(terrain.column_cells, 0, "{terrain:?}");
}

#[test]
fn a_tube_pressed_against_another_gets_a_changed_grasp_or_none() {
    let p = planner();
    let tube = tube_on_ground(0.0, 1.0, Vector3::x());
    // The neighbour lies alongside, seal sections 0.5 mm apart (centres 23.5 mm apart).
    let other = tube_on_ground(0.0, 1.0235, Vector3::x());
    let check = p.check(&tube, &ground().normal, &Scene { ground: ground(), tubes: std::slice::from_ref(&other), terrain: None });
    eprintln!("pressed against a neighbour: {check:?}");
    assert!(check.rejected.tube > 0 && !check.terrain_checked, "{check:?}");
    assert!(check.changed, "{check:?}");
    if check.feasible {
        assert!(check.tilt_deg != 0.0 || check.shift_mm != 0.0, "{check:?}");
        assert!(check.clearance_mm >= 1.0, "{check:?}");
    } else {
        // Every candidate was refused.
        assert_eq!(check.rejected.tube + check.rejected.ground + check.rejected.terrain, check.candidates_tried, "{check:?}");
        assert_eq!(check.t_cam_grasp, tube.grasp_frame(&ground().normal));
    }
    // With the neighbour 60 mm away the plain grasp stands again.
    let far = tube_on_ground(0.0, 1.06, Vector3::x());
    let check = p.check(&tube, &ground().normal, &Scene { ground: ground(), tubes: std::slice::from_ref(&far), terrain: None });
    assert!(check.feasible && !check.changed && check.rejected.tube == 0, "{check:?}");
}

#[test]
fn a_neighbour_over_one_end_shifts_the_grasp_along_the_axis() {
    let p = planner();
    let tube = tube_on_ground(0.0, 1.0, Vector3::x());
    // A second tube crossing over the seal end's side at right angles, lying 30 mm higher
    // (on the first), centred 5 mm from the first's centre along its axis.
    let other = TubeAxisPose::new(0, 0.5, Vector3::new(0.005, 1.5 - 0.0115 - 0.030, 1.0), Vector3::z(), 0.9).unwrap();
    let check = p.check(&tube, &ground().normal, &Scene { ground: ground(), tubes: std::slice::from_ref(&other), terrain: None });
    assert!(check.feasible && check.rejected.tube > 0, "{check:?}");
    // The fingers (x half width 10 mm) stand clear of the crossing tube (radius up to 11.5 mm).
    assert!(check.shift_mm < -15.0, "{check:?}");
}

#[test]
fn graspable_interval_follows_the_seal_end_and_its_confidence() {
    let p = planner();
    // Seal end toward +x: body from -60 to 15 mm, less 10 mm each side for the fingers.
    let t = tube_on_ground(0.0, 1.0, Vector3::x());
    let (lo, hi) = p.graspable_interval(&t).unwrap();
    assert!((lo + 0.050).abs() < 1e-12 && (hi - 0.005).abs() < 1e-12);
    // Seal end toward -x: mirrored.
    let t = tube_on_ground(0.0, 1.0, -Vector3::x());
    let (lo, hi) = p.graspable_interval(&t).unwrap();
    assert!((lo + 0.005).abs() < 1e-12 && (hi - 0.050).abs() < 1e-12);
    // Unsure which end: body either way round, -15 to 15 mm, less the fingers.
    let mut t = tube_on_ground(0.0, 1.0, Vector3::x());
    t.end_confidence = 0.5;
    let (lo, hi) = p.graspable_interval(&t).unwrap();
    assert!((lo + 0.005).abs() < 1e-12 && (hi - 0.005).abs() < 1e-12);
}

/// Analytic distance of a point to a solid (0 inside).
fn distance_to(shape: &Obstacle, p: &Point3<f64>) -> f64 {
    match shape {
        Obstacle::Box(pose, c) => {
            let q = pose.inverse_transform_point(p);
            (q.coords.abs() - c.half_extents).map(|v| v.max(0.0)).norm()
        }
        Obstacle::Cyl(pose, c) => {
            let q = pose.inverse_transform_point(p);
            let radial = (q.x.hypot(q.z) - c.radius).max(0.0);
            let axial = (q.y.abs() - c.half_height).max(0.0);
            radial.hypot(axial)
        }
        Obstacle::Ground(g) => g.height_of(&p.coords).max(0.0),
        Obstacle::Columns(t) => {
            let c = t.columns.as_ref().unwrap();
            c.shapes().iter().map(|(iso, s)| distance_to(&Obstacle::Box(t.pose * iso, *s.as_cuboid().unwrap()), p)).fold(f64::INFINITY, f64::min)
        }
    }
}

enum Obstacle {
    Box(Isometry3<f64>, Cuboid),
    Cyl(Isometry3<f64>, Cylinder),
    Ground(GroundPlane),
    Columns(Terrain),
}

fn random_pose(rng: &mut ChaCha8Rng, spread: f64) -> Isometry3<f64> {
    let t = Vector3::new(rng.random_range(-spread..spread), 1.45 + rng.random_range(-spread..spread), 1.0 + rng.random_range(-spread..spread));
    let axis = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
    Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_scaled_axis(axis.normalize() * rng.random_range(0.0..3.1)))
}

#[test]
fn parry_distances_agree_with_brute_force_point_tests() {
    let mut rng = ChaCha8Rng::seed_from_u64(33);
    let gripper = GripperModel::default();
    let model = TubeModel::default();
    let (mut apart, mut overlapping) = (0, 0);
    for trial in 0..240 {
        // A gripper part (finger or palm, swept or not) at a random pose near the obstacle.
        let parts = gripper.parts_swept(if trial % 2 == 0 { 0.0 } else { 0.05 });
        let part = &parts[trial % 3];
        let part_pose = random_pose(&mut rng, 0.05) * part.pose;
        let obstacle = match trial % 4 {
            0 => Obstacle::Box(random_pose(&mut rng, 0.05), Cuboid::new(Vector3::new(rng.random_range(0.004..0.04), rng.random_range(0.004..0.04), rng.random_range(0.004..0.04)))),
            1 => {
                let tube = TubeAxisPose::new(0, 1.0, random_pose(&mut rng, 0.05).translation.vector, Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), 0.3), 0.9).unwrap();
                let s = TubeSolid::new(&model, &tube);
                let (pose, cyl) = s.sections[trial / 4 % s.sections.len()];
                Obstacle::Cyl(pose, cyl)
            }
            2 => {
                let n = Vector3::new(rng.random_range(-0.3..0.3), -1.0, rng.random_range(-0.3..0.3));
                Obstacle::Ground(GroundPlane::from_point_normal(&Vector3::new(0.0, 1.45 + rng.random_range(-0.05..0.05), 1.0), &n))
            }
            _ => {
                // Bumpy terrain: random points up to 50 mm high.
                let g = GroundPlane::new(Vector3::new(0.0, -1.0, 0.0), -1.5).unwrap();
                let pts: Vec<Point3<f64>> = (0..3000).map(|_| Point3::new(rng.random_range(-0.1..0.1), 1.5 - rng.random_range(0.0..0.05f64).powi(2) / 0.05, 1.0 + rng.random_range(-0.1..0.1))).collect();
                let around = TubeAxisPose::new(0, 1.0, Vector3::new(0.0, 1.49, 1.0), Vector3::x(), 0.9).unwrap();
                let t = Terrain::from_points(&pts, &g, &around, 0.08, &[], &model, &TerrainSettings { cell_mm: 20.0, min_points: 1, min_height_mm: 0.0, ..TerrainSettings::default() }, 0.0);
                Obstacle::Columns(t)
            }
        };
        let (pose, shape): (Isometry3<f64>, Box<dyn Shape>) = match &obstacle {
            Obstacle::Box(p, c) => (*p, Box::new(*c)),
            Obstacle::Cyl(p, c) => (*p, Box::new(*c)),
            Obstacle::Ground(g) => (Isometry3::translation(g.normal.x * g.offset, g.normal.y * g.offset, g.normal.z * g.offset), Box::new(HalfSpace::new(nalgebra::Unit::new_normalize(g.normal)))),
            Obstacle::Columns(t) => (t.pose, Box::new(t.columns.clone().unwrap())),
        };
        let d = query::distance(&part_pose, &part.shape, &pose, shape.as_ref()).unwrap();
        // Brute force: random points in the part's volume and on its faces.
        let h = part.shape.half_extents;
        let (mut inside, mut nearest) = (0usize, f64::INFINITY);
        for k in 0..6000 {
            let mut q = Vector3::new(rng.random_range(-h.x..h.x), rng.random_range(-h.y..h.y), rng.random_range(-h.z..h.z));
            if k % 2 == 0 {
                let axis = k / 2 % 3;
                q[axis] = if k / 6 % 2 == 0 { h[axis] } else { -h[axis] };
            }
            let p = part_pose.transform_point(&Point3::from(q));
            let dist = distance_to(&obstacle, &p);
            inside += (dist == 0.0) as usize;
            nearest = nearest.min(dist);
        }
        if d > 0.0 {
            apart += 1;
            assert_eq!(inside, 0, "trial {trial}: parry says {d} m apart but sampled points lie inside");
            assert!(nearest >= d - 1e-9, "trial {trial}: a point {nearest} m away, parry {d}");
            assert!(nearest - d < 0.0015, "trial {trial}: nearest sampled point {nearest} m, parry {d}");
        } else {
            // Touching: the penetration depth says how deep; deep ones must show sampled points inside.
            let depth = query::contact(&part_pose, &part.shape, &pose, shape.as_ref(), 0.0).unwrap().map_or(0.0, |c| -c.dist);
            if depth > 0.002 {
                overlapping += 1;
                assert!(inside > 0, "trial {trial}: parry says they overlap by {depth} m but no sampled point is inside");
            }
        }
    }
    assert!(apart >= 60 && overlapping >= 40, "both cases tested: {apart} apart, {overlapping} overlapping");
}

#[test]
fn gripper_file_errors_name_the_file_and_field() {
    let err = |text: &str| GripperModel::from_toml_str(text, Path::new("g.toml")).unwrap_err().to_string();
    assert_eq!(GripperModel::default().finger.width, 0.020);
    assert_eq!(err(&DEFAULT_GRIPPER_TOML.replace("width = 0.020", "width = -0.02")), "g.toml: invalid finger.width: must be a positive number of metres, got -0.02");
    assert_eq!(err(&DEFAULT_GRIPPER_TOML.replace("thickness = 0.020", "thickness = nan")), "g.toml: invalid palm.thickness: must be a positive number of metres, got NaN");
    assert_eq!(err(&DEFAULT_GRIPPER_TOML.replace("tip_depth = 0.003", "tip_depth = 0.07")), "g.toml: invalid grasp.tip_depth: must be at least 0 and less than finger.length (0.06 m), got 0.07");
    let e = err(&DEFAULT_GRIPPER_TOML.replace("[palm]", "[palm]\ncolour = \"red\""));
    assert!(e.starts_with("g.toml: ") && e.contains("unknown field `colour`"), "{e}");
    let e = err(&DEFAULT_GRIPPER_TOML.replace("approach = 0.050", ""));
    assert!(e.starts_with("g.toml: ") && e.contains("missing field `approach`"), "{e}");
    // An opening narrower than the tube's 23 mm seal section is refused by the planner.
    let mut narrow = GripperModel::default();
    narrow.grasp.opening = 0.02;
    let e = GraspPlanner::new(narrow, PlannerSettings::default(), &TubeModel::default()).unwrap_err().to_string();
    assert_eq!(e, "invalid grasp.opening: 0.02 m does not clear the tube's widest section (0.023 m across)");
    let e = GraspPlanner::new(GripperModel::default(), PlannerSettings { tilt_step_deg: 0.0, ..PlannerSettings::default() }, &TubeModel::default()).unwrap_err().to_string();
    assert_eq!(e, "invalid grasp planner tilt_step_deg: 0 is out of range");
    let missing = GripperModel::load(Path::new("/nonexistent/gripper.toml")).unwrap_err().to_string();
    assert!(missing.starts_with("/nonexistent/gripper.toml: "), "{missing}");
}

#[test]
fn grasp_check_round_trips_through_json() {
    let p = planner();
    let tube = tube_on_ground(0.0, 1.0, Vector3::x());
    let check = p.check(&tube, &ground().normal, &Scene { ground: ground(), tubes: &[], terrain: None });
    let text = serde_json::to_string(&check).unwrap();
    assert!(text.contains("\"feasible\":true") && text.contains("\"T_cam_grasp\"") && text.contains("\"terrain_checked\":false"), "{text}");
    let back: tubeloc_grasp::GraspCheck = serde_json::from_str(&text).unwrap();
    assert_eq!(back.feasible, check.feasible);
    assert_eq!(back.rejected, check.rejected);
    assert!(back.t_cam_grasp.distance(&check.t_cam_grasp).0 < 1e-9);
}

#[test]
fn reported_clearance_is_exact_beyond_the_ranking_cap() {
    // Ranking counts clearance only up to 2 mm here; the chosen grasp's figure is still exact.
    let p = GraspPlanner::new(GripperModel::default(), PlannerSettings { enough_clearance_mm: 2.0, ..PlannerSettings::default() }, &TubeModel::default()).unwrap();
    let tube = tube_on_ground(0.0, 1.0, Vector3::x());
    let check = p.check(&tube, &ground().normal, &Scene { ground: ground(), tubes: &[], terrain: None });
    assert!(check.feasible && !check.changed && (check.clearance_mm - 8.5).abs() < 1e-6, "{check:?}");
}
