//! Grasp check speed per tube: [`GraspPlanner::check`] (all candidates, fingers and palm swept
//! along the approach, against the scene), and building a tube's terrain from stereo points.
//!
//! Scenes (camera frame, level camera 1.5 m above flat ground, tube 1 m ahead):
//! - `ground_only`: the mono case, the ground plane alone;
//! - `stereo_clutter`: two neighbouring tubes (one alongside 40 mm away, one crossing near an
//!   end) and terrain columns from 10,000 points (a 30 mm rock beside one end, noisy ground);
//! - `terrain_from_points`: building that terrain (binning, medians, compound).
//!
//! Run: `cargo bench -p tubeloc-grasp --bench clearance` (criterion reports the median per tube).

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use tubeloc_core::{GroundPlane, TubeAxisPose, TubeModel};
use tubeloc_grasp::{GraspPlanner, GripperModel, PlannerSettings, Scene, Terrain, TerrainSettings};

fn bench(c: &mut Criterion) {
    let ground = GroundPlane::new(Vector3::new(0.0, -1.0, 0.0), -1.5).unwrap();
    let model = TubeModel::default();
    let planner = GraspPlanner::new(GripperModel::default(), PlannerSettings::default(), &model).unwrap();
    let tube = TubeAxisPose::new(0, 0.9, Vector3::new(0.0, 1.4885, 1.0), Vector3::x(), 0.9).unwrap();
    let others = [TubeAxisPose::new(0, 0.8, Vector3::new(0.0, 1.4885, 1.04), Vector3::x(), 0.9).unwrap(), TubeAxisPose::new(0, 0.7, Vector3::new(0.09, 1.4885, 1.0), Vector3::z(), 0.9).unwrap()];
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let r = planner.terrain_radius();
    let points: Vec<Point3<f64>> = (0..10_000)
        .map(|_| {
            let (x, z) = (rng.random_range(-r..r), 1.0 + rng.random_range(-r..r));
            let rock = if (-0.08..-0.04).contains(&x) && (0.95..0.97).contains(&z) { 0.03 } else { 0.0 };
            Point3::new(x, 1.5 - rock + rng.random_range(-0.002..0.002), z)
        })
        .collect();
    let all: Vec<TubeAxisPose> = std::iter::once(tube.clone()).chain(others.iter().cloned()).collect();
    let settings = TerrainSettings::default();
    let terrain = Terrain::from_points(&points, &ground, &tube, r, &all, &model, &settings, 0.0);
    let plain = planner.check(&tube, &ground.normal, &Scene { ground, tubes: &[], terrain: None });
    let cluttered = Scene { ground, tubes: &others, terrain: Some(&terrain) };
    let busy = planner.check(&tube, &ground.normal, &cluttered);
    eprintln!("ground only: {plain:?}\nstereo clutter ({terrain:?}): {busy:?}");
    c.bench_function("grasp_check_ground_only", |b| b.iter(|| planner.check(black_box(&tube), &ground.normal, &Scene { ground, tubes: &[], terrain: None })));
    c.bench_function("grasp_check_stereo_clutter", |b| b.iter(|| planner.check(black_box(&tube), &ground.normal, &cluttered)));
    c.bench_function("grasp_check_tubes_only", |b| b.iter(|| planner.check(black_box(&tube), &ground.normal, &Scene { ground, tubes: &others, terrain: None })));
    c.bench_function("grasp_check_terrain_only", |b| b.iter(|| planner.check(black_box(&tube), &ground.normal, &Scene { ground, tubes: &[], terrain: Some(&terrain) })));
    c.bench_function("terrain_from_10k_points", |b| b.iter(|| Terrain::from_points(black_box(&points), &ground, &tube, r, &all, &model, &settings, 0.0)));
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(4));
    targets = bench
}
criterion_main!(benches);
