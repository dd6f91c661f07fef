//! Rig YAML interchange with OpenCV: a file written by `cv2.FileStorage` is read by our reader,
//! and a file we write is read by `cv2.FileStorage` with the same numbers.
//!
//! Needs python3 with OpenCV, which CI does not install: the test is `#[ignore]`d; run it with
//! `cargo test --release -p tubeloc-calib --test integration opencv_yaml:: -- --ignored`. It fails when python3
//! or cv2 is missing.

use std::path::Path;
use std::process::Command;
use tubeloc_calib::yaml::{load_rig_yaml, save_rig_yaml};

fn peer(args: &[&str]) -> std::process::Output {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/opencv_yaml_peer.py");
    let out = Command::new("python3").arg(&script).args(args).output().unwrap_or_else(|e| panic!("python3 not runnable ({e})"));
    assert_ne!(out.status.code(), Some(3), "cv2/numpy not installed: pip install opencv-contrib-python-headless numpy");
    assert!(out.status.success(), "peer failed: {}", String::from_utf8_lossy(&out.stderr));
    out
}

#[test]
#[ignore = "needs python3 with opencv-contrib-python-headless (pip install opencv-contrib-python-headless numpy); run with --ignored"]
fn reads_opencv_filestorage_yaml_and_opencv_reads_ours() {
    let dir = tempfile::tempdir().unwrap();
    let cv_yaml = dir.path().join("cv.yaml");
    peer(&["write", cv_yaml.to_str().unwrap()]);
    let rig = load_rig_yaml(&cv_yaml).unwrap();
    assert_eq!(rig.cameras.len(), 2);
    assert_eq!(rig.stereo_pairs, vec![("L20".to_string(), "R20".to_string())]);
    let r = &rig.cameras[1];
    assert_eq!((r.name.as_str(), r.model.width, r.model.height), ("R20", 1368, 912));
    assert_eq!((r.model.fx, r.model.fy, r.model.cx, r.model.cy), (861.0, 862.0, 683.5, 455.5));
    assert_eq!((r.model.distortion.k1, r.model.distortion.p2, r.model.distortion.k3), (-0.1, -0.002, 0.0005));
    // OpenCV's R, T map rig points into the camera: x_cam = R x_rig + T.
    let t_cam_rig = r.t_rig_cam.inverse();
    assert!((t_cam_rig.translation() - nalgebra::Vector3::new(-0.2, 0.001, 0.002)).norm() < 1e-12);
    assert!((rig.baseline("L20", "R20").unwrap() - 0.2f64.hypot(0.0)).abs() < 2e-3);

    let ours = dir.path().join("ours.yaml");
    save_rig_yaml(&rig, &ours).unwrap();
    let out = peer(&["read", ours.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["camera_count"], 2);
    for (c, cv) in rig.cameras.iter().zip(v["cameras"].as_array().unwrap()) {
        assert_eq!(cv["name"], c.name.as_str());
        let k = &cv["K"];
        assert_eq!((k[0][0].as_f64().unwrap(), k[1][1].as_f64().unwrap(), k[0][2].as_f64().unwrap()), (c.model.fx, c.model.fy, c.model.cx));
        let t = c.t_rig_cam.inverse();
        for i in 0..3 {
            assert!((cv["T"][i].as_f64().unwrap() - t.translation()[i]).abs() < 1e-15);
        }
    }
}
