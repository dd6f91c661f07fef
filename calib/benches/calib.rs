//! Benchmarks: AprilTag detection on a real 799x533 photo, the tag-pair pose, and the 4-camera
//! rig calibration of a 36-view synthetic set (corners only). `cargo bench -p tubeloc-calib`.

use criterion::{criterion_group, criterion_main, Criterion};
use std::path::Path;
use tubeloc_calib::{calibrate, load_calib_set, CalibrationOptions, CornerSource, DetectorConfig, TagDetector};
use tubeloc_synth::calib_set::{default_rig, generate, write_calib_set, BoardLayout, CalibSetConfig};

fn bench(c: &mut Criterion) {
    let photo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/apriltag/apriltag_test_data/34085369442_304b6bafd9_c.jpg");
    if let Ok(img) = image::open(&photo) {
        let img = img.to_luma8();
        let mut det = TagDetector::new(DetectorConfig::default()).unwrap();
        c.bench_function("detect_real_photo_799x533_1thread", |b| b.iter(|| det.detect_image(&img).unwrap()));
    } else {
        eprintln!("skipping detection bench: {} absent", photo.display());
    }
    let cfg = CalibSetConfig { views: 36, seed: 11, corner_noise_px: 0.2, render: false, scale: 0.25, ..Default::default() };
    let set = generate(&default_rig(), &BoardLayout::default_board(), &cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_calib_set(dir.path(), &set, || {}).unwrap();
    let loaded = load_calib_set(dir.path(), CornerSource::Noisy, None).unwrap();
    let mut g = c.benchmark_group("rig");
    g.sample_size(10);
    g.bench_function("calibrate_4cam_36views", |b| b.iter(|| calibrate(&loaded.input, &CalibrationOptions::default()).unwrap()));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
