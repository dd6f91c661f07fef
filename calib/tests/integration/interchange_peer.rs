//! The exported calibration files project points where tubeloc's camera model does, each read
//! with its own convention by an independent reader (scripts/interchange_peer.py):
//! - OpenCV FileStorage YAML: `cv2.FileStorage` + `cv2.projectPoints` with each camera's R, T;
//! - ROS camera_info: PyYAML + `cv2.projectPoints`, and each stereo pair's rectified pixels from
//!   the files' R and P in ROS's convention (P projects points of the pair's stereo frame);
//! - kalibr camchain: PyYAML, kalibr's type checks, and the pinhole-radtan equations written out
//!   in Python, points carried from cam0 down the chain by T_cn_cnm1.
//!
//! Needs python3 with opencv-python-headless, numpy and PyYAML (`.ci/run` installs them). Without
//! them the test fails when the CI environment variable is set and is skipped (with a message)
//! otherwise.

use nalgebra::{Point2, Point3};
use std::path::Path;
use std::process::Command;
use tubeloc_calib::interchange::{kalibr, ros};
use tubeloc_calib::yaml::save_rig_yaml;
use tubeloc_core::{PairRectification, Rig};

/// Pixels spread over each camera's image, at depths 1-6 m, as rig-frame points.
fn points_rig(rig: &Rig) -> Vec<Point3<f64>> {
    let mut pts = Vec::new();
    for c in &rig.cameras {
        let m = &c.model;
        for (i, fx) in [0.02, 0.3, 0.5, 0.71, 0.98].iter().enumerate() {
            for (j, fy) in [0.03, 0.4, 0.66, 0.97].iter().enumerate() {
                let px = Point2::new(fx * (m.width as f64 - 1.0), fy * (m.height as f64 - 1.0));
                let z = 1.0 + (i * 4 + j) as f64 * 0.25;
                pts.push(c.t_rig_cam.transform_point(&m.unproject_depth(&px, z)));
            }
        }
    }
    pts
}

fn max_px_error(ours: &[Point2<f64>], theirs: &serde_json::Value) -> f64 {
    let theirs = theirs.as_array().expect("pixel list");
    assert_eq!(ours.len(), theirs.len());
    ours.iter().zip(theirs).map(|(a, b)| (a.x - b[0].as_f64().unwrap()).abs().max((a.y - b[1].as_f64().unwrap()).abs())).fold(0.0, f64::max)
}

fn xyz(p: &Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

#[test]
fn exported_files_project_where_our_camera_model_does() {
    let rig = tubeloc_synth::calib_set::default_rig();
    assert!(rig.cameras.iter().all(|c| c.model.distortion.k3 != 0.0), "the OpenCV and ROS files must be tested with k3");
    let mut rig_k3_free = rig.clone();
    for c in &mut rig_k3_free.cameras {
        c.model.distortion.k3 = 0.0;
    }
    let dir = tempfile::tempdir().unwrap();
    let cv_path = dir.path().join("rig.yaml");
    save_rig_yaml(&rig, &cv_path).unwrap();
    let ros_files = ros::save_rig_camera_infos(&rig, &dir.path().join("ros")).unwrap();
    let chain_path = dir.path().join("camchain.yaml");
    kalibr::save_camchain(&rig_k3_free, &chain_path).unwrap();

    let pts = points_rig(&rig);
    let cam_pts = |r: &Rig, name: &str| -> Vec<Point3<f64>> {
        let t = r.camera(name).unwrap().t_rig_cam.inverse();
        pts.iter().map(|p| t.transform_point(p)).collect()
    };
    let infos: Vec<ros::CameraInfo> = ros_files.iter().map(|f| ros::CameraInfo::load(f).unwrap()).collect();
    let job = serde_json::json!({
        "opencv": {"file": cv_path, "points_rig": pts.iter().map(xyz).collect::<Vec<_>>()},
        "ros": ros_files.iter().zip(&infos).map(|(f, info)| serde_json::json!({"file": f, "points_cam": cam_pts(&rig, &info.name).iter().map(xyz).collect::<Vec<_>>()})).collect::<Vec<_>>(),
        "ros_pairs": rig.stereo_pairs.iter().map(|(l, r)| {
            let file = |n: &str| &ros_files[infos.iter().position(|i| i.name == n).unwrap()];
            serde_json::json!({"left": file(l), "right": file(r), "points_left": cam_pts(&rig, l).iter().map(xyz).collect::<Vec<_>>(), "points_right": cam_pts(&rig, r).iter().map(xyz).collect::<Vec<_>>()})
        }).collect::<Vec<_>>(),
        "kalibr": {"file": chain_path, "points_cam0": cam_pts(&rig_k3_free, &rig.cameras[0].name).iter().map(xyz).collect::<Vec<_>>()},
    });
    let job_path = dir.path().join("job.json");
    std::fs::write(&job_path, serde_json::to_vec(&job).unwrap()).unwrap();

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/interchange_peer.py");
    let out = match Command::new("python3").arg(&script).arg(&job_path).output() {
        Ok(o) => o,
        Err(e) if std::env::var_os("CI").is_none() => return eprintln!("skipped: python3 not runnable ({e})"),
        Err(e) => panic!("python3 not runnable ({e})"),
    };
    if out.status.code() == Some(3) {
        let why = String::from_utf8_lossy(&out.stderr);
        assert!(std::env::var_os("CI").is_none(), "{why}: python3 -m pip install opencv-python-headless pyyaml");
        return eprintln!("skipped: {why}");
    }
    assert!(out.status.success(), "peer failed: {}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();

    let mut worst = [0.0f64; 3];
    // OpenCV FileStorage YAML + cv2.projectPoints, rig-frame points through each camera's R, T.
    for c in &rig.cameras {
        let ours: Vec<Point2<f64>> = cam_pts(&rig, &c.name).iter().map(|p| c.model.project(p).unwrap()).collect();
        let err = max_px_error(&ours, &v["opencv"][&c.name]);
        worst[0] = worst[0].max(err);
        assert!(err < 1e-6, "OpenCV YAML, camera {}: {err:.3e} px from cv2.projectPoints", c.name);
    }
    // ROS camera_info: distorted pixels, and the rectified pair's rows and disparities.
    let ros_out = v["ros"].as_array().unwrap();
    assert_eq!(ros_out.len(), rig.cameras.len(), "one camera_info per camera of a rig whose cameras are in at most one pair");
    for (info, o) in infos.iter().zip(ros_out) {
        let c = rig.camera(&info.name).unwrap();
        assert_eq!(o["name"], c.name.as_str());
        assert_eq!((o["size"][0].as_u64().unwrap(), o["size"][1].as_u64().unwrap()), (c.model.width as u64, c.model.height as u64));
        let ours: Vec<Point2<f64>> = cam_pts(&rig, &c.name).iter().map(|p| c.model.project(p).unwrap()).collect();
        let err = max_px_error(&ours, &o["pixels"]);
        worst[1] = worst[1].max(err);
        assert!(err < 1e-6, "ROS camera_info {}: {err:.3e} px from cv2.projectPoints", c.name);
    }
    for ((l, r), o) in rig.stereo_pairs.iter().zip(v["ros_pairs"].as_array().unwrap()) {
        let rect = PairRectification::new(&rig.camera(l).unwrap().model, &rig.camera(r).unwrap().model, &rig.relative_pose(l, r).unwrap()).unwrap();
        let xy = |p: &serde_json::Value| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap());
        let rows = o["left"].as_array().unwrap().iter().zip(o["right"].as_array().unwrap()).zip(o["right_own"].as_array().unwrap());
        for (((a, b), own), p) in rows.zip(cam_pts(&rig, l)) {
            let p_rect = rect.r_left * p.coords;
            let ours = rect.rectified.project(&Point3::from(p_rect)).unwrap();
            let ((ua, va), (ub, vb), (uo, vo)) = (xy(a), xy(b), xy(own));
            assert!((ua - ours.x).abs() < 1e-6 && (va - ours.y).abs() < 1e-6, "pair {l},{r}: left rectified pixel ({ua}, {va}) vs ours {ours:?}");
            assert!((va - vb).abs() < 1e-6, "pair {l},{r}: rectified rows differ, {va} vs {vb}");
            let disparity = rect.rectified.fx * rect.baseline / p_rect.z;
            assert!(((ua - ub) - disparity).abs() < 1e-6, "pair {l},{r}: disparity {} vs f·B/Z = {disparity}", ua - ub);
            assert!((ub - uo).abs() < 1e-6 && (vb - vo).abs() < 1e-6, "pair {l},{r}: P_right on the stereo frame ({ub}, {vb}) vs the right camera's own rectified ray ({uo}, {vo})");
        }
    }
    // kalibr camchain with the pinhole-radtan equations; points given in cam0's frame.
    for (i, c) in rig_k3_free.cameras.iter().enumerate() {
        let ours: Vec<Point2<f64>> = cam_pts(&rig_k3_free, &c.name).iter().map(|p| c.model.project(p).unwrap()).collect();
        let err = max_px_error(&ours, &v["kalibr"][format!("cam{i}")]);
        worst[2] = worst[2].max(err);
        assert!(err < 1e-6, "kalibr camchain, cam{i} ({}): {err:.3e} px from the radtan equations", c.name);
    }
    eprintln!("largest pixel differences (OpenCV {}): OpenCV YAML {:.1e} px, ROS camera_info {:.1e} px, kalibr camchain {:.1e} px", v["cv2_version"], worst[0], worst[1], worst[2]);
}
