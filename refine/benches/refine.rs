//! Mono refinement speed: one tube per iteration on a rayon pool of one thread, excluding
//! detection and image loading. The scene is the test renderer's (1024x768, tube at ~1.2 m,
//! seed 3 mm / 2 deg off the truth). A second case refines the tube from a mask detection (the
//! learned segmenter's kind of seed: mask, axis seed, no template pose) with the ground plane,
//! the path of `tubeloc refine --detections --ground auto` (coarse search, colour-free end
//! decision, mask check, image-axis prior).
//!
//! The allocator keeps freed memory as `tubeloc` does ([`tubeloc_core::heap`]).
//!
//! Run: `cargo bench -p tubeloc-refine --bench refine` (criterion reports the median time per
//! tube).

#[path = "../tests/integration/common/mod.rs"]
mod common;

use common::*;
use criterion::{criterion_group, criterion_main, Criterion};

fn bench(c: &mut Criterion) {
    // As the `tubeloc` binary does (`tubeloc_core::heap`).
    assert!(tubeloc_core::heap::keep_freed_memory());
    let ss = speed_scene();
    let (refiner, seed, input) = (&ss.refiner, &ss.seed, ss.input());
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let p = pool.install(|| refiner.refine_seed(&input, seed, 0, 1.0, None));
    assert!(p.converged, "bench scene does not converge: {:?}", p.failure);
    eprintln!("bench tube: {} iterations, error {:.2} mm", p.residuals.iterations, (p.centre - ss.scene.truth.centre).norm() * 1e3);
    c.bench_function("refine_mono_one_tube_1_thread", |b| b.iter(|| pool.install(|| refiner.refine_seed(&input, seed, 0, 1.0, None))));

    for (name, range) in [("1.2m", (1.1, 1.3)), ("2.5m", (2.4, 2.6))] {
        let (scene, det) = mask_seed_scene(range);
        let input = scene.ground_input();
        let p = pool.install(|| refiner.refine(&input, &det, None));
        assert!(p.converged, "mask-seed bench does not converge: {:?}", p.failure);
        eprintln!("mask seed at {name}: {:.0} px long, error {:.2} mm", det.axis_seed.as_ref().unwrap().length_px, (p.centre - scene.truth.centre).norm() * 1e3);
        c.bench_function(&format!("refine_mono_mask_seed_ground_{name}_1_thread"), |b| b.iter(|| pool.install(|| refiner.refine(&input, &det, None))));
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench
}
criterion_main!(benches);
