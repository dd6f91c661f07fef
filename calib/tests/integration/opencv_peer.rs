//! Our calibration vs OpenCV's calibrateCamera / stereoCalibrate on the same corners of the
//! same synthetic set, both against the truth.
//!
//! Needs python3 with OpenCV, which CI does not install: the test is `#[ignore]`d; run it with
//! `cargo test --release -p tubeloc-calib --test integration opencv_peer:: -- --ignored`. It fails when python3
//! or cv2 is missing.

use std::process::Command;
use tubeloc_calib::{calibrate, load_calib_set, CalibrationOptions, CornerSource};
use tubeloc_synth::calib_set::{default_rig, generate, write_calib_set, BoardLayout, CalibSetConfig};

#[test]
#[ignore = "needs python3 with opencv-contrib-python-headless (pip install opencv-contrib-python-headless numpy); run with --ignored"]
fn compare_with_opencv_on_same_corners() {
    let noise = 0.2;
    let cfg = CalibSetConfig { views: 36, seed: 11, corner_noise_px: noise, render: false, scale: 0.25, ..Default::default() };
    let set = generate(&default_rig(), &BoardLayout::default_board(), &cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_calib_set(dir.path(), &set, || {}).unwrap();
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/opencv_calib_peer.py");
    let out = Command::new("python3").arg(&script).arg(dir.path()).arg("noisy").output().unwrap_or_else(|e| panic!("python3 not runnable ({e})"));
    assert_ne!(out.status.code(), Some(3), "cv2/numpy not installed: pip install opencv-contrib-python-headless numpy");
    assert!(out.status.success(), "peer failed: {}", String::from_utf8_lossy(&out.stderr));
    let cv: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let loaded = load_calib_set(dir.path(), CornerSource::Noisy, None).unwrap();
    let t0 = std::time::Instant::now();
    let ours = calibrate(&loaded.input, &CalibrationOptions::default()).unwrap();
    let our_s = t0.elapsed().as_secs_f64();
    eprintln!("camera | truth fx | ours fx err (rel) | opencv fx err (rel) | ours pp err px | opencv pp err px | ours rms | opencv rms");
    for (c, t) in ours.cameras.iter().zip(&loaded.truth.cameras) {
        let o = &cv["cameras"][&c.name];
        let (ofx, ofy, ocx, ocy) = (o["fx"].as_f64().unwrap(), o["fy"].as_f64().unwrap(), o["cx"].as_f64().unwrap(), o["cy"].as_f64().unwrap());
        let tm = &t.model;
        let ours_f = ((c.model.fx - tm.fx) / tm.fx).abs().max(((c.model.fy - tm.fy) / tm.fy).abs());
        let cv_f = ((ofx - tm.fx) / tm.fx).abs().max(((ofy - tm.fy) / tm.fy).abs());
        let ours_pp = (c.model.cx - tm.cx).hypot(c.model.cy - tm.cy);
        let cv_pp = (ocx - tm.cx).hypot(ocy - tm.cy);
        eprintln!("{} | {:.3} | {:.2e} | {:.2e} | {:.3} | {:.3} | {:.4} | {:.4}", c.name, tm.fx, ours_f, cv_f, ours_pp, cv_pp, c.rms_px, o["rms"].as_f64().unwrap());
        assert!(ours_f < 1e-3 && ours_pp < 1.0);
        // OpenCV calibrates each camera alone (no rig constraint): only a sanity bound here.
        assert!(cv_f < 5e-3 && cv_pp < 5.0, "opencv is far off: input problem?");
        // Same data, same model: the RMS figures must agree closely.
        assert!((c.rms_px - o["rms"].as_f64().unwrap()).abs() < 0.02);
    }
    for (l, r, b) in &ours.baselines {
        let truth = loaded.truth.baseline(l, r).unwrap();
        let cvb = cv["baselines"][format!("{l}-{r}")].as_f64().unwrap();
        eprintln!("baseline {l}-{r}: truth {:.3} mm, ours err {:.3} mm, opencv stereoCalibrate err {:.3} mm", truth * 1e3, (b - truth).abs() * 1e3, (cvb - truth).abs() * 1e3);
        assert!((b - truth).abs() < 0.5e-3);
    }
    eprintln!("wall time: ours (4-camera joint) {our_s:.2} s, opencv (4 calibrateCamera + 2 stereoCalibrate) {:.2} s", cv["seconds"].as_f64().unwrap());
}
