//! Benchmarks: AprilTag detection on a real 799x533 photo, the 4-camera rig calibration of a
//! 36-view synthetic set (corners only), and side by side with OpenCV: the rig calibration on
//! the same noisy corners of the default calibration set (4 cameras x 30 views), and the
//! resampling of the real MSL rear Hazcam frame (CAHVORE, 1024²) into its linear camera
//! against `cv2.remap` on the same map.
//! `cargo bench -p tubeloc-calib`; the side-by-side parts alone:
//! `cargo bench -p tubeloc-calib --bench calib -- opencv` (needs python3 with
//! opencv-python-headless and numpy, else it says so and skips; `CALIB_PEER_RUNS` sets the
//! number of interleaved runs, default 9; `CALIB_PEER_PYTHON` the interpreter).

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
        let out = match Command::new(peer_python()).arg(&script).arg(dir.path()).arg("noisy").output() {
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

/// The Python interpreter of the OpenCV peers: `CALIB_PEER_PYTHON`, else `python3`.
fn peer_python() -> String {
    std::env::var("CALIB_PEER_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// A `.npy` file of a C-order array of `shape` with the little-endian samples `bytes` of the
/// numpy type `descr` (`<f4`, `|u1`).
fn write_npy(path: &Path, descr: &str, shape: &[usize], bytes: &[u8]) {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({},), }}", dims.join(", "));
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(bytes);
    std::fs::write(path, out).unwrap();
}

/// The real rear Hazcam frame resampled into its linear camera: building the map and applying
/// it (ours), and `cv2.remap` of the same image by the same map, interleaved run by run;
/// medians, their ratio, and how far the two outputs differ.
fn fisheye_side_by_side() {
    use tubeloc_calib::interchange::{linearize::LinearResampling, pds_label::read_resampled_label_camera};
    let with = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real_mars/with_cameras");
    let (label, png) = (with.join("labels/RLB_701384675RAS_F0933408RHAZ00337M1.LBL"), with.join("images/RLB_701384675RAS_F0933408RHAZ00337M1.png"));
    let (Ok(Some((cam, Some(fisheye)))), Ok(img)) = (read_resampled_label_camera(&label), image::open(&png)) else {
        return eprintln!("skipping the fisheye side by side: {} or its image absent", label.display());
    };
    let img = image::DynamicImage::ImageLuma8(img.to_luma8());
    let runs: usize = std::env::var("CALIB_PEER_RUNS").ok().and_then(|v| v.parse().ok()).unwrap_or(9);
    let size = (img.width(), img.height());
    let (w, h) = (cam.camera.model.width as usize, cam.camera.model.height as usize);
    let dir = tempfile::tempdir().unwrap();
    let map = LinearResampling::new(&fisheye, &cam.camera, size);
    let (mut xs, mut ys) = (Vec::with_capacity(w * h), Vec::with_capacity(w * h));
    for v in 0..h as u32 {
        for u in 0..w as u32 {
            let s = map.source_of(u, v).map_or([-10.0f32; 2], |p| [p.x as f32, p.y as f32]);
            xs.extend_from_slice(&s[0].to_le_bytes());
            ys.extend_from_slice(&s[1].to_le_bytes());
        }
    }
    let f = |n: &str| dir.path().join(n);
    write_npy(&f("image.npy"), "|u1", &[size.1 as usize, size.0 as usize], img.as_luma8().unwrap().as_raw());
    write_npy(&f("mapx.npy"), "<f4", &[h, w], &xs);
    write_npy(&f("mapy.npy"), "<f4", &[h, w], &ys);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/opencv_remap_peer.py");
    let (mut build_s, mut apply_s, mut cv_s) = (Vec::new(), Vec::new(), Vec::new());
    let mut ours = None;
    for _ in 0..runs {
        let t0 = Instant::now();
        let m = LinearResampling::new(&fisheye, &cam.camera, size);
        build_s.push(t0.elapsed().as_secs_f64());
        let t1 = Instant::now();
        ours = Some(m.apply(&img));
        apply_s.push(t1.elapsed().as_secs_f64());
        let out = match Command::new(peer_python()).arg(&script).args([f("image.npy"), f("mapx.npy"), f("mapy.npy"), f("out.npy")]).arg("1").output() {
            Ok(o) if o.status.success() => o,
            Ok(o) => return eprintln!("skipping the fisheye side by side: peer failed ({})", String::from_utf8_lossy(&o.stderr).trim()),
            Err(e) => return eprintln!("skipping the fisheye side by side: python not runnable ({e})"),
        };
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        cv_s.push(v["seconds"][0].as_f64().unwrap());
    }
    let npy = std::fs::read(f("out.npy")).unwrap();
    let cv = &npy[npy.len() - w * h..];
    let ours = ours.unwrap().into_luma8().into_raw();
    let diffs: Vec<i32> = ours.iter().zip(cv).map(|(&a, &b)| (a as i32 - b as i32).abs()).collect();
    let (bm, am, cm) = (median(&mut build_s), median(&mut apply_s), median(&mut cv_s));
    println!("\nfisheye resampling side by side: MSL rear Hazcam CAHVORE {}x{} -> its linear camera, grey 8-bit, {runs} interleaved runs", size.0, size.1);
    println!("| | median ms |");
    println!("|---|---|");
    println!("| tubeloc: map (CAHVORE projection of every pixel's ray, rayon) | {:.1} |", bm * 1e3);
    println!("| tubeloc: apply the map (bilinear, rayon) | {:.1} |", am * 1e3);
    println!("| OpenCV cv2.remap, INTER_LINEAR, same map | {:.1} |", cm * 1e3);
    println!("ratio apply / cv2.remap (medians): {:.2}; outputs differ by at most {} DN (mean {:.3})", am / cm, diffs.iter().max().unwrap(), diffs.iter().sum::<i32>() as f64 / diffs.len() as f64);
}

fn main() {
    let filter_opencv_only = std::env::args().skip(1).any(|a| a == "opencv");
    if !filter_opencv_only {
        benches();
        Criterion::default().configure_from_args().final_summary();
    }
    if std::env::args().any(|a| a == "--bench") || filter_opencv_only {
        opencv_side_by_side();
        fisheye_side_by_side();
    }
}
