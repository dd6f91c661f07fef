//! Mono refinement speed: one tube per iteration on a rayon pool of one thread, excluding
//! detection and image loading. The scene is the test renderer's (1024x768, tube at ~1.2 m,
//! seed 3 mm / 2 deg off the truth).
//!
//! Run: `cargo bench -p tubeloc-refine --bench refine` (criterion reports the median time per
//! tube).

#[path = "../tests/common/mod.rs"]
mod common;

use common::*;
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Rotation3, Unit, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tubeloc_refine::{AxisState, RefineConfig, RefineInput, Refiner, Scene as FitScene, Seed};

fn bench(c: &mut Criterion) {
    let model = default_model();
    let cam = camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let (truth, up, gd) = random_truth(&mut rng, &model, &cam, (1.1, 1.3));
    let sc = render(&model, &cam, truth, up, gd, None, 4242, 0.01);
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let r = Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::new(0.3, -0.5, 0.8)), 2f64.to_radians());
    let seed = Seed { state: AxisState { c: truth.centre + Vector3::new(0.003, -0.002, 0.003), a: r * truth.axis }, end_known: false };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene::default() };
    let p = pool.install(|| refiner.refine_seed(&input, &seed, 0, 1.0, None));
    assert!(p.converged, "bench scene does not converge: {:?}", p.failure);
    eprintln!("bench tube: {} iterations, error {:.2} mm", p.residuals.iterations, (p.centre - truth.centre).norm() * 1e3);
    c.bench_function("refine_mono_one_tube_1_thread", |b| b.iter(|| pool.install(|| refiner.refine_seed(&input, &seed, 0, 1.0, None))));
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench
}
criterion_main!(benches);
