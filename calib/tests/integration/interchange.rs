//! Calibration interchange: rig -> each format -> rig round trips through the one reader
//! (`read_rig`), ROS camera_info rectification, refusals, and errors for malformed files that
//! name the file and the field.

use nalgebra::{Matrix3, Rotation3, Vector3};
use std::path::{Path, PathBuf};
use tubeloc_calib::interchange::{detect_rig_format, kalibr, ros, RigFormat};
use tubeloc_calib::read_rig;
use tubeloc_calib::yaml::{rig_to_yaml, save_rig_yaml};
use tubeloc_core::{PairRectification, Pose, Rig};

fn default_rig() -> Rig {
    tubeloc_synth::calib_set::default_rig()
}

/// The default rig with k3 = 0 (what kalibr's radtan can carry), its cameras rotated and the
/// first camera away from the rig origin so that the rig frame must survive the trip.
fn rig_without_k3() -> Rig {
    let mut rig = default_rig();
    for (i, c) in rig.cameras.iter_mut().enumerate() {
        c.model.distortion.k3 = 0.0;
        c.t_rig_cam = Pose::from_parts(Rotation3::from_euler_angles(0.01 * i as f64, -0.02, 0.03), Vector3::new(0.0, 0.001 * i as f64, 0.0)) * c.t_rig_cam;
    }
    rig
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(1.0)
}

/// Names, sizes and pairs equal; intrinsics, distortion and poses equal to 1e-12 relative.
fn assert_same_rig(a: &Rig, b: &Rig, what: &str) {
    assert_eq!(a.stereo_pairs, b.stereo_pairs, "{what}: stereo pairs");
    assert_eq!(a.cameras.len(), b.cameras.len(), "{what}: camera count");
    for (x, y) in a.cameras.iter().zip(&b.cameras) {
        assert_eq!((&x.name, x.model.width, x.model.height), (&y.name, y.model.width, y.model.height), "{what}");
        let (dx, dy) = (&x.model.distortion, &y.model.distortion);
        let pa = [x.model.fx, x.model.fy, x.model.cx, x.model.cy, dx.k1, dx.k2, dx.p1, dx.p2, dx.k3];
        let pb = [y.model.fx, y.model.fy, y.model.cx, y.model.cy, dy.k1, dy.k2, dy.p1, dy.p2, dy.k3];
        for (k, (u, v)) in pa.iter().zip(&pb).enumerate() {
            assert!(rel(*u, *v) <= 1e-12, "{what}: camera {} parameter {k}: {u} vs {v}", x.name);
        }
        let (ra, rb) = (x.t_rig_cam.rotation(), y.t_rig_cam.rotation());
        let (ta, tb) = (x.t_rig_cam.translation(), y.t_rig_cam.translation());
        for k in 0..9 {
            assert!(rel(ra[k], rb[k]) <= 1e-12, "{what}: camera {} rotation {ra} vs {rb}", x.name);
        }
        for k in 0..3 {
            assert!(rel(ta[k], tb[k]) <= 1e-12, "{what}: camera {} translation {ta} vs {tb}", x.name);
        }
    }
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn every_rig_format_round_trips_through_read_rig() {
    let dir = tempfile::tempdir().unwrap();
    for rig in [default_rig(), rig_without_k3()] {
        let json = dir.path().join("rig.json");
        rig.save_json(&json).unwrap();
        assert_same_rig(&rig, &read_rig(&json).unwrap(), "tubeloc JSON");
        // File names say nothing: the OpenCV file is called .json, the camchain .txt.
        let cv = dir.path().join("opencv.json");
        save_rig_yaml(&rig, &cv).unwrap();
        assert_same_rig(&rig, &read_rig(&cv).unwrap(), "OpenCV YAML");
    }
    let rig = rig_without_k3();
    let chain = dir.path().join("camchain.txt");
    kalibr::save_camchain(&rig, &chain).unwrap();
    let back = read_rig(&chain).unwrap();
    assert_same_rig(&rig, &back, "kalibr camchain");
    // T_cn_cnm1 of cam1 is cam1 <- cam0.
    let text = std::fs::read_to_string(&chain).unwrap();
    assert!(text.contains("cam1:\n  T_cn_cnm1:\n  - [") && text.contains("distortion_model: radtan") && text.contains("rostopic: /L20/image_raw"), "{text}");
    for (path, format) in [(&json_path(dir.path(), &rig), RigFormat::TubelocJson), (&chain, RigFormat::KalibrCamchain)] {
        assert_eq!(detect_rig_format(&std::fs::read_to_string(path).unwrap()), Ok(format));
    }
    assert_eq!(detect_rig_format(&rig_to_yaml(&rig)), Ok(RigFormat::OpencvYaml));
}

fn json_path(dir: &Path, rig: &Rig) -> PathBuf {
    let p = dir.join("again.json");
    rig.save_json(&p).unwrap();
    p
}

#[test]
fn ros_camera_info_round_trips_cameras_and_pair_geometry() {
    let rig = default_rig();
    let dir = tempfile::tempdir().unwrap();
    let files = ros::save_rig_camera_infos(&rig, &dir.path().join("ros")).unwrap();
    let names: Vec<String> = files.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    assert_eq!(names, ["L40.yaml", "L20.yaml", "R20.yaml", "R40.yaml"]);
    let info = |n: &str| ros::CameraInfo::load(&dir.path().join("ros").join(format!("{n}.yaml"))).unwrap();
    for c in &rig.cameras {
        let i = info(&c.name);
        assert_eq!((i.name.as_str(), &i.model), (c.name.as_str(), &c.model), "intrinsics and k1 k2 p1 p2 k3 are exact");
        // A ROS file read as a rig: one camera at the origin.
        let one = read_rig(&dir.path().join("ros").join(format!("{}.yaml", c.name))).unwrap();
        assert_eq!((one.cameras.len(), &one.cameras[0].model, one.stereo_pairs.len()), (1, &c.model, 0));
    }
    for (l, r) in &rig.stereo_pairs {
        let (li, ri) = (info(l), info(r));
        let t_lr = rig.relative_pose(l, r).unwrap();
        let rect = PairRectification::new(&li.model, &ri.model, &t_lr).unwrap();
        assert_eq!((li.rectification, li.projection, ri.rectification, ri.projection), (rect.r_left, rect.p1, rect.r_right, rect.p2));
        // The pair's geometry back from R1, R2 and P2: R = R1ᵀ R2, t = R1ᵀ (B, 0, 0), B = -P2[0][3] / f.
        let b = -ri.projection[(0, 3)] / ri.projection[(0, 0)];
        assert!(rel(b, t_lr.translation().norm()) < 1e-12 && b > 0.0, "baseline {b}");
        let r_lr: Matrix3<f64> = li.rectification.transpose() * ri.rectification;
        let t = li.rectification.transpose() * Vector3::new(b, 0.0, 0.0);
        assert!((r_lr - t_lr.rotation()).abs().max() < 1e-12 && (t - t_lr.translation()).abs().max() < 1e-12);
        assert_eq!(li.projection[(0, 3)], 0.0);
    }
    let text = std::fs::read_to_string(&files[2]).unwrap();
    assert!(text.contains("camera_name: \"R20\"") && text.contains("distortion_model: plumb_bob") && text.contains("projection_matrix:\n  rows: 3\n  cols: 4\n  data: ["), "{text}");
}

#[test]
fn ros_export_gives_a_camera_in_no_pair_identity_rectification_and_names_extra_pairs() {
    let mut rig = default_rig();
    rig.stereo_pairs = vec![("L20".into(), "R20".into()), ("L20".into(), "R40".into())];
    let files = ros::rig_camera_infos(&rig).unwrap();
    let names: Vec<&str> = files.iter().map(|f| f.file_name.as_str()).collect();
    assert_eq!(names, ["L40.yaml", "L20.yaml", "L20.L20-R40.yaml", "R20.yaml", "R40.yaml"]);
    let mono = &files[0].info;
    assert_eq!(mono.rectification, Matrix3::identity());
    assert_eq!(mono.projection.fixed_view::<3, 3>(0, 0).into_owned(), mono.model.k_matrix());
    rig.cameras[0].name = "left/cam".into();
    rig.stereo_pairs.clear();
    let e = ros::rig_camera_infos(&rig).unwrap_err().to_string();
    assert_eq!(e, "invalid camera name: \"left/cam\" cannot name a ROS camera_info file (letters, digits, `_`, `-`, `.` only, not starting with `.`)");
}

#[test]
fn camchain_refuses_k3_naming_the_camera_and_the_term() {
    let e = kalibr::rig_to_camchain(&default_rig()).unwrap_err().to_string();
    assert_eq!(e, "invalid camera \"L40\": k3 = -0.003 cannot be written to a kalibr camchain: its radtan model has k1 k2 r1 r2 only (calibrate with --fix-k3, or use the OpenCV YAML or ROS camera_info files, which carry k3)");
}

/// A camchain as kalibr itself writes it: no tubeloc extensions, integer zeros, block rows.
const KALIBR_WRITTEN: &str = "cam0:
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  distortion_model: radtan
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  T_cn_cnm1:
  - [0.9999972564779, 0.002312067192424, 0.000376008102415, -0.110073808127187]
  - [-0.002317135723281, 0.999898048506644, 0.014089835846691, 0.000399121547014]
  - [-0.000343393120525, -0.014090668452714, 0.999900662637729, -0.000853702503357]
  - [0, 0, 0, 1]
  cam_overlaps: [0]
  camera_model: pinhole
  distortion_coeffs: [-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]
  distortion_model: radtan
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  resolution: [752, 480]
  rostopic: /stereo/right/image_raw
";

#[test]
fn a_camchain_written_by_kalibr_reads_with_cam0_as_rig_frame() {
    let dir = tempfile::tempdir().unwrap();
    let rig = read_rig(&write(dir.path(), "camchain-euroc.yaml", KALIBR_WRITTEN)).unwrap();
    assert_eq!(rig.cameras.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(), ["cam0", "stereo_right"]);
    assert_eq!(rig.stereo_pairs, [("cam0".to_string(), "stereo_right".to_string())]);
    assert_eq!(rig.cameras[0].t_rig_cam, Pose::identity());
    let m = &rig.cameras[1].model;
    assert_eq!((m.width, m.height, m.fx, m.cy, m.distortion.p2, m.distortion.k3), (752, 480, 457.587, 255.238, -3.55590700e-05, 0.0));
    // T_cn_cnm1 maps cam0 points into cam1: cam1's centre sits at -Rᵀt in cam0.
    let c1 = rig.cameras[1].t_rig_cam.translation();
    assert!((c1.x - 0.110073).abs() < 1e-5 && rig.baseline("cam0", "stereo_right").unwrap() > 0.11);
}

#[test]
fn read_rig_names_the_file_and_the_formats_it_tried() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "notes.txt", "just: text\nmore: 3\n");
    let e = read_rig(&p).unwrap_err().to_string();
    assert_eq!(
        e,
        format!("{}: not a rig file in a known format; tried tubeloc JSON (does not start with `{{`), a PDS camera list (does not start with `[`), a PDS3 label (does not start with `PDS_VERSION_ID`), OpenCV FileStorage YAML (no `%YAML:1.0` first line), kalibr camchain and ROS camera_info (a YAML mapping without `cam0` (kalibr) or `camera_matrix` (ROS))", p.display())
    );
    let e = read_rig(&write(dir.path(), "bad.yaml", "cam0: [unclosed\n")).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}: not a rig file", dir.path().join("bad.yaml").display())) && e.contains("not YAML"), "{e}");
    let e = read_rig(&dir.path().join("absent.json")).unwrap_err().to_string();
    assert!(e.contains("absent.json"), "{e}");
    // A JSON list is read as PDS cameras, and its errors say so.
    assert_eq!(detect_rig_format("  [ {} ]"), Ok(RigFormat::PdsCameras));
    let e = read_rig(&write(dir.path(), "cams.json", "[{\"image\": \"a.png\"}]")).unwrap_err().to_string();
    assert!(e.contains("cams.json") && e.contains("entry 0") && e.contains("image_width"), "{e}");
}

/// Every prefix of a valid file is an error naming the file (or, rarely, a valid smaller rig),
/// never a panic.
fn truncations_never_panic(text: &str, path: &Path) {
    for cut in (0..text.len()).filter(|c| text.is_char_boundary(*c)).step_by(7) {
        std::fs::write(path, &text[..cut]).unwrap();
        if let Err(e) = read_rig(path) {
            assert!(e.to_string().contains(&*path.file_name().unwrap().to_string_lossy()), "cut {cut}: {e}");
        }
    }
}

/// `text` with the number right after `anchor` (up to the next `,`) replaced by `with`.
fn replace_first_number(text: &str, anchor: &str, with: &str) -> String {
    let a = text.find(anchor).unwrap_or_else(|| panic!("{anchor:?} not in the file")) + anchor.len();
    let b = a + text[a..].find(',').unwrap();
    format!("{}{with}{}", &text[..a], &text[b..])
}

/// Reads `text` from a file called `name`; the error message.
fn error_of(dir: &Path, name: &str, text: &str) -> String {
    read_rig(&write(dir, name, text)).unwrap_err().to_string()
}

#[test]
fn malformed_camchain_errors_name_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let good = kalibr::rig_to_camchain(&rig_without_k3()).unwrap();
    truncations_never_panic(&good, &dir.path().join("cut.yaml"));
    let d = dir.path();
    let name = |f: &str| d.join(f).display().to_string();
    // Missing field.
    let missing = good.replacen("  intrinsics: [", "  intrinsics_gone: [", 2).replacen("  intrinsics_gone: [", "  intrinsics: [", 1);
    assert_eq!(error_of(d, "missing.yaml", &missing), format!("{}: cam1.intrinsics: missing", name("missing.yaml")));
    // Wrong-size matrix and vector.
    let cam1 = good.find("cam1:").unwrap();
    let i = cam1 + good[cam1..].find("  - [0.0, 0.0, 0.0, 1.0]\n").unwrap();
    let three_rows = format!("{}{}", &good[..i], &good[i + "  - [0.0, 0.0, 0.0, 1.0]\n".len()..]);
    assert_eq!(error_of(d, "rows.yaml", &three_rows), format!("{}: cam1.T_cn_cnm1: expected a 4x4 matrix, got 3 rows", name("rows.yaml")));
    let short = good.replacen("  resolution: [5472, 3648]", "  resolution: [5472]", 1);
    assert_eq!(error_of(d, "res.yaml", &short), format!("{}: cam0.resolution: expected [width, height]", name("res.yaml")));
    let five = good.replacen("  distortion_coeffs: [", "  distortion_coeffs: [0.0, ", 1);
    assert_eq!(error_of(d, "dist.yaml", &five), format!("{}: cam0.distortion_coeffs: expected 4 numbers, got 5", name("dist.yaml")));
    // NaN and not-a-number.
    let nan = replace_first_number(&good, "  intrinsics: [", ".nan");
    assert_eq!(error_of(d, "nan.yaml", &nan), format!("{}: cam0.intrinsics: element 0 is NaN, not a finite number", name("nan.yaml")));
    let word = good.replacen("  distortion_coeffs: [", "  distortion_coeffs: [abc, ", 1);
    assert!(error_of(d, "word.yaml", &word).starts_with(&format!("{}: cam0.distortion_coeffs: expected 4 numbers, got 5", name("word.yaml"))));
    // Unsupported models are named, not converted.
    let eq = good.replacen("distortion_model: radtan", "distortion_model: equidistant", 1);
    assert_eq!(error_of(d, "eq.yaml", &eq), format!("{}: cam0.distortion_model: \"equidistant\" is not supported: tubeloc's lens model is radtan (k1 k2 r1 r2)", name("eq.yaml")));
    let omni = good.replacen("camera_model: pinhole", "camera_model: omni", 1);
    assert_eq!(error_of(d, "omni.yaml", &omni), format!("{}: cam0.camera_model: \"omni\" is not supported: tubeloc's camera model is pinhole", name("omni.yaml")));
    // A rotation that is not one.
    let row = cam1 + good[cam1..].find("  - [").unwrap() + "  - [".len();
    let skew = format!("{}2.0{}", &good[..row], &good[row + good[row..].find(',').unwrap()..]);
    assert!(error_of(d, "skew.yaml", &skew).starts_with(&format!("{}: cam1.T_cn_cnm1: invalid pose: rotation is not orthonormal", name("skew.yaml"))));
}

#[test]
fn malformed_camera_info_errors_name_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let files = ros::save_rig_camera_infos(&default_rig(), &d.join("ros")).unwrap();
    let good = std::fs::read_to_string(&files[1]).unwrap();
    truncations_never_panic(&good, &d.join("cut.yaml"));
    let name = |f: &str| d.join(f).display().to_string();
    let missing = good.replacen("image_height: 3648\n", "", 1);
    assert_eq!(error_of(d, "m.yaml", &missing), format!("{}: image_height: missing", name("m.yaml")));
    let rows = good.replacen("projection_matrix:\n  rows: 3", "projection_matrix:\n  rows: 4", 1);
    assert_eq!(error_of(d, "p.yaml", &rows), format!("{}: projection_matrix: expected a 3x4 matrix, got 4x4", name("p.yaml")));
    let short = good.replacen("distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [", "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.0, ", 1);
    assert_eq!(error_of(d, "d.yaml", &short), format!("{}: distortion_coefficients.data: expected 5 numbers, got 6 (a 1x5 matrix)", name("d.yaml")));
    let nan = replace_first_number(&good, "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [", ".nan");
    assert_eq!(error_of(d, "n.yaml", &nan), format!("{}: camera_matrix.data: element 0 is NaN, not a finite number (a 3x3 matrix)", name("n.yaml")));
    let model = good.replacen("distortion_model: plumb_bob", "distortion_model: rational_polynomial", 1);
    assert_eq!(error_of(d, "r.yaml", &model), format!("{}: distortion_model: \"rational_polynomial\" is not supported: tubeloc's camera model is plumb_bob (k1 k2 p1 p2 k3)", name("r.yaml")));
}

#[test]
fn malformed_opencv_yaml_errors_name_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let good = rig_to_yaml(&default_rig());
    truncations_never_panic(&good, &d.join("cut.yaml"));
    let name = |f: &str| d.join(f).display().to_string();
    let missing = good.replacen("cam2_image_width: 5472\n", "", 1);
    assert_eq!(error_of(d, "m.yaml", &missing), format!("{}: cam2_image_width: missing", name("m.yaml")));
    let wrong = good.replacen("cam1_T: !!opencv-matrix\n   rows: 3\n   cols: 1", "cam1_T: !!opencv-matrix\n   rows: 1\n   cols: 3", 1);
    assert_eq!(error_of(d, "t.yaml", &wrong), format!("{}: cam1_T: expected 3x1, got 1x3", name("t.yaml")));
    let nan = replace_first_number(&good, "cam0_camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ ", ".Nan");
    let e = error_of(d, "n.yaml", &nan);
    assert!(e.starts_with(&format!("{}: cam0_camera_matrix: invalid camera: all intrinsics must be finite numbers", name("n.yaml"))), "{e}");
}

#[test]
fn malformed_json_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = d.join("rig.json");
    default_rig().save_json(&p).unwrap();
    let good = std::fs::read_to_string(&p).unwrap();
    truncations_never_panic(&good, &d.join("cut.json"));
    let e = error_of(d, "m.json", &good.replacen("\"fx\"", "\"focal\"", 1));
    assert!(e.starts_with(&name_of(d, "m.json")) && e.contains("fx"), "{e}");
}

fn name_of(d: &Path, f: &str) -> String {
    d.join(f).display().to_string()
}

#[test]
fn one_camera_model_reads_as_a_mono_rig() {
    // What `--camera` takes is also a rig: the camera, named `camera`, at the rig origin.
    let dir = tempfile::tempdir().unwrap();
    let model = default_rig().cameras[0].model.clone();
    let path = dir.path().join("cam.json");
    std::fs::write(&path, serde_json::to_string(&model).unwrap()).unwrap();
    let rig = read_rig(&path).unwrap();
    let expected = Rig { cameras: vec![tubeloc_core::RigCamera { name: "camera".into(), model, t_rig_cam: Pose::identity() }], stereo_pairs: Vec::new() };
    assert_same_rig(&expected, &rig, "camera JSON");
    // A camera with a field missing is refused naming the file, as `--camera` refuses it.
    std::fs::write(&path, r#"{"width": 100, "height": 80, "fx": 100}"#).unwrap();
    let err = read_rig(&path).unwrap_err().to_string();
    assert!(err.contains("cam.json") && err.contains("fy"), "{err}");
}
