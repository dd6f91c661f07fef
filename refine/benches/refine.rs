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

fn bench(c: &mut Criterion) {
    let ss = speed_scene();
    let (refiner, seed, input) = (&ss.refiner, &ss.seed, ss.input());
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let p = pool.install(|| refiner.refine_seed(&input, seed, 0, 1.0, None));
    assert!(p.converged, "bench scene does not converge: {:?}", p.failure);
    eprintln!("bench tube: {} iterations, error {:.2} mm", p.residuals.iterations, (p.centre - ss.scene.truth.centre).norm() * 1e3);
    c.bench_function("refine_mono_one_tube_1_thread", |b| b.iter(|| pool.install(|| refiner.refine_seed(&input, seed, 0, 1.0, None))));
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench
}
criterion_main!(benches);
