//! Benchmarks: AprilTag detection on a real 799x533 photo, the 4-camera rig calibration of a
//! 36-view synthetic set (corners only), and the rig calibration side by side with OpenCV on
//! the same noisy corners of the default calibration set (4 cameras x 30 views).
//! `cargo bench -p tubeloc-calib`; the side-by-side part alone:
//! `cargo bench -p tubeloc-calib --bench calib -- opencv` (needs python3 with
//! opencv-python-headless and numpy, else it says so and skips; `CALIB_PEER_RUNS` sets the
//! number of interleaved runs, default 9).

use criterion::{criterion_group, Criterion};
use nalgebra::Point2;
use std::path::Path;
use std::process::Command;
use std::time::Instant;
use tubeloc_calib::{calibrate, load_calib_set, CalibrationOptions, CornerSource, DetectorConfig, TagDetector};
use tubeloc_core::{CameraModel, Distortion};
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

fn median(xs: &mut [f64]) -> f64 {
    xs.sort_by(f64::total_cmp);
    let n = xs.len();
    if n % 2 == 1 {
        xs[n / 2]
    } else {
        0.5 * (xs[n / 2 - 1] + xs[n / 2])
    }
}

/// Camera-model error: RMS over a 16 x 12 pixel grid of the distance between each pixel and
/// its true ray (truth's undistortion) projected through the estimated model, pixels.
fn model_error_px(truth: &CameraModel, est: &CameraModel) -> f64 {
    let (mut s, mut n) = (0.0, 0);
    for i in 0..16 {
        for j in 0..12 {
            let px = Point2::new((i as f64 + 0.5) * truth.width as f64 / 16.0, (j as f64 + 0.5) * truth.height as f64 / 12.0);
            let (x, y) = truth.normalize(&px);
            s += (est.project_normalized(x, y) - px).norm_squared();
            n += 1;
        }
    }
    (s / n as f64).sqrt()
}

/// Our calibration and OpenCV's (`scripts/opencv_calib_peer.py`: 4 calibrateCamera + 2
/// stereoCalibrate) on the same corners, interleaved run by run; medians and their ratio.
fn opencv_side_by_side() {
    let runs: usize = std::env::var("CALIB_PEER_RUNS").ok().and_then(|v| v.parse().ok()).unwrap_or(9);
    let cfg = CalibSetConfig { render: false, ..Default::default() };
    let set = generate(&default_rig(), &BoardLayout::default_board(), &cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_calib_set(dir.path(), &set, || {}).unwrap();
    let loaded = load_calib_set(dir.path(), CornerSource::Noisy, None).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/opencv_calib_peer.py");
    let (mut ours_s, mut cv_s) = (Vec::new(), Vec::new());
    let (mut ours, mut cv) = (None, None);
    for _ in 0..runs {
        let t0 = Instant::now();
        ours = Some(calibrate(&loaded.input, &CalibrationOptions::default()).unwrap());
        ours_s.push(t0.elapsed().as_secs_f64());
        let out = match Command::new("python3").arg(&script).arg(dir.path()).arg("noisy").output() {
            Ok(o) if o.status.success() => o,
            Ok(o) => return eprintln!("skipping the OpenCV side by side: peer failed ({})", String::from_utf8_lossy(&o.stderr).trim()),
            Err(e) => return eprintln!("skipping the OpenCV side by side: python3 not runnable ({e})"),
        };
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        cv_s.push(v["seconds"].as_f64().unwrap());
        cv = Some(v);
    }
    let (ours, cv) = (ours.unwrap(), cv.unwrap());
    let (mut our_err, mut cv_err) = (Vec::new(), Vec::new());
    for (c, t) in ours.cameras.iter().zip(&loaded.truth.cameras) {
        our_err.push(model_error_px(&t.model, &c.model));
        let o = &cv["cameras"][&c.name];
        let d: Vec<f64> = o["dist"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        let m = CameraModel {
            width: t.model.width,
            height: t.model.height,
            fx: o["fx"].as_f64().unwrap(),
            fy: o["fy"].as_f64().unwrap(),
            cx: o["cx"].as_f64().unwrap(),
            cy: o["cy"].as_f64().unwrap(),
            distortion: Distortion { k1: d[0], k2: d[1], p1: d[2], p2: d[3], k3: d[4] },
        };
        cv_err.push(model_error_px(&t.model, &m));
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (om, cm) = (median(&mut ours_s.clone()), median(&mut cv_s.clone()));
    println!("\nrig calibration side by side, noisy corners of the default set (4 cameras x 30 views, {} corners), {runs} interleaved runs", loaded.input.observations.iter().map(|o| o.image.len()).sum::<usize>());
    println!("| | median s | min s | max s | camera-model error px (mean of 4) |");
    println!("|---|---|---|---|---|");
    let mm = |v: &[f64]| (v.iter().copied().fold(f64::INFINITY, f64::min), v.iter().copied().fold(0.0f64, f64::max));
    let ((omin, omax), (cmin, cmax)) = (mm(&ours_s), mm(&cv_s));
    println!("| tubeloc (joint rig adjustment, Schur + faer) | {om:.3} | {omin:.3} | {omax:.3} | {:.3} |", mean(&our_err));
    println!("| OpenCV (4 calibrateCamera + 2 stereoCalibrate) | {cm:.3} | {cmin:.3} | {cmax:.3} | {:.3} |", mean(&cv_err));
    println!("ratio tubeloc / OpenCV (medians): {:.2}", om / cm);
}

fn main() {
    let filter_opencv_only = std::env::args().skip(1).any(|a| a == "opencv");
    if !filter_opencv_only {
        benches();
        Criterion::default().configure_from_args().final_summary();
    }
    if std::env::args().any(|a| a == "--bench") || filter_opencv_only {
        opencv_side_by_side();
    }
}
