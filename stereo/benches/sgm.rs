//! SGM speed on a 1024x768 synthetic pair with 128 disparities (8 and 4 paths).
//!
//! Also writes the pair, its exact disparity and visibility mask to
//! `$CARGO_TARGET_DIR/stereo_bench/` (default `target/stereo_bench/`) so that
//! `scripts/stereo_bench.sh` can time OpenCV StereoSGBM on the very same images.
//! Run: `cargo bench -p tubeloc-stereo --bench sgm` or `scripts/stereo_bench.sh`.

use criterion::{criterion_group, criterion_main, Criterion};
use std::path::PathBuf;
use std::time::Duration;
use tubeloc_stereo::synthetic::bench_scene;
use tubeloc_stereo::{Paths, SgmMatcher, SgmParams};

fn out_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from).unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target"));
    target.join("stereo_bench")
}

fn bench(c: &mut Criterion) {
    let pair = bench_scene(1024, 768, 42);
    let dir = out_dir();
    std::fs::create_dir_all(&dir).unwrap();
    let save = |name: &str, p: &tubeloc_core::Plane<u8>| {
        image::GrayImage::from_raw(p.width as u32, p.height as u32, p.data.clone()).unwrap().save(dir.join(name)).unwrap();
    };
    save("left.png", &pair.left);
    save("right.png", &pair.right);
    save("visible.png", &tubeloc_core::Plane::from_vec(1024, 768, pair.visible.data.iter().map(|&v| v * 255).collect()));
    std::fs::write(dir.join("gt.pfm"), tubeloc_stereo::io::encode_pfm(&pair.disparity)).unwrap();

    let mut g = c.benchmark_group("sgm_1024x768_d128");
    g.sample_size(10).measurement_time(Duration::from_secs(12)).warm_up_time(Duration::from_secs(2));
    for (name, paths) in [("eight_paths", Paths::Eight), ("four_paths", Paths::Four)] {
        let mut m = SgmMatcher::new(SgmParams { num_disparities: 128, paths, ..SgmParams::default() }).unwrap();
        let d = m.compute(&pair.left, &pair.right).unwrap();
        std::fs::write(dir.join(format!("ours_{name}.pfm")), tubeloc_stereo::io::encode_pfm(&d)).unwrap();
        g.bench_function(name, |b| b.iter(|| m.compute(&pair.left, &pair.right).unwrap()));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
