//! Hardening of the `tubeloc` program (the hardening issue): bad numbers refused while the
//! command line is parsed (exit 2, the flag named, no output written), AprilTag detection on
//! images the C detector cannot take, template libraries too large to build, stale temporaries,
//! outputs that are not regular files, and a closed stdout.

use crate::common;

use common::*;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

/// A grey PNG of the given size.
fn png(dir: &Path, w: u32, h: u32) -> PathBuf {
    let path = dir.join(format!("img_{w}x{h}.png"));
    image::GrayImage::from_fn(w, h, |x, y| image::Luma([if (x / 3 + y / 2) % 2 == 0 { 20 } else { 230 }])).save(&path).unwrap();
    path
}

#[test]
fn bad_numbers_and_argument_errors_exit_2_naming_the_flag_and_writing_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let img = png(d, 64, 64);
    let out = d.join("out");
    let o = p(&out);
    let img = p(&img);
    let out_json = d.join("out.json");
    let oj = p(&out_json);
    let out_tlt = d.join("out.tlt");
    let ot = p(&out_tlt);
    // (arguments, text the message must contain)
    let cases: Vec<(Vec<&str>, &str)> = vec![
        // The cases.
        (vec!["stereo", "--left", img, "--right", img, "--sigma-d", "NaN", "--out", o], "--sigma-d"),
        (vec!["stereo", "--left", img, "--right", img, "--sigma-d", "inf", "--out", o], "--sigma-d"),
        (vec!["eval", "--gt", "gt.json", "--poses", "p.json", "--match-mm", "NaN", "--out", o], "--match-mm"),
        (vec!["detect", "--method", "line2d", "--image", img, "--nms-iou", "NaN", "--out", oj], "--nms-iou"),
        (vec!["detect", "--method", "line2d", "--image", img, "--ring-inner", "7", "--ring-outer", "6", "--out", oj], "--ring-inner"),
        (vec!["synth", "calib", "--views", "0", "--out", o], "--views"),
        (vec!["synth", "--shard", "3/2", "--out", o], "--shard"),
        (vec!["synth", "--scenes", "0", "--out", o], "--scenes"),
        (vec!["synth", "--resolution", "0", "--out", o], "--resolution"),
        (vec!["stereo", "--left", img, "--right", img, "--paths", "3", "--out", o], "--paths"),
        (vec!["synth", "--preset", "tiny"], "--out"),
        (vec!["calib", "detect", "--decimate", "200", img, "--out", oj], "--decimate"),
        (vec!["calib", "detect", "--decimate", "2.5", img, "--out", oj], "--decimate"),
        (vec!["templates", "build", "--distances", "1:4:1e-9", "--out", ot], "templates"),
        (vec!["templates", "build", "--step-deg", "0.01", "--out", ot], "--step-deg"),
        // More of the same kind.
        (vec!["eval", "--gt", "gt.json", "--poses", "p.json", "--min-visible", "1.5", "--out", o], "--min-visible"),
        (vec!["eval", "--gt", "gt.json", "--poses", "p.json", "--match-mm=-5", "--out", o], "--match-mm"),
        (vec!["detect", "--method", "line2d", "--image", img, "--threshold", "120", "--out", oj], "--threshold"),
        (vec!["detect", "--method", "line2d", "--image", img, "--max-detections", "0", "--out", oj], "--max-detections"),
        (vec!["detect", "--method", "line2d", "--image", img, "--far-scale", "0.5", "--out", oj], "--far-scale"),
        (vec!["detect", "--method", "line2d", "--image", img, "--far-scale", "NaN", "--out", oj], "--far-scale"),
        (vec!["detect", "--method", "line2d", "--image", img, "--ground-range", "1.2:0.8", "--out", oj], "--ground-range"),
        (vec!["detect", "--method", "line2d", "--image", img, "--ground-range", "0:1", "--out", oj], "--ground-range"),
        (vec!["detect", "--method", "line2d", "--image", img, "--ground-range", "NaN:1", "--out", oj], "--ground-range"),
        (vec!["detect", "--method", "line2d", "--image", img, "--ground", "0,-1,0,-1.9", "--out", oj], "--camera"),
        (vec!["synth", "--scale", "NaN", "--out", o], "--scale"),
        (vec!["synth", "--shard", "1", "--out", o], "--shard"),
        (vec!["synth", "calib", "--noise", "NaN", "--out", o], "--noise"),
        (vec!["synth", "calib", "--scale", "0", "--out", o], "--scale"),
        (vec!["synth", "stereo", "--pairs-per-scene", "0", "--out", o], "--pairs-per-scene"),
        (vec!["stereo", "--left", img, "--right", img, "--disparities", "100", "--out", o], "--disparities"),
        (vec!["stereo", "--left", img, "--right", img, "--roi", "0,0,0,10", "--out", o], "--roi"),
        (vec!["train", "--train", "ds", "--lr", "NaN", "--out", oj], "--lr"),
        (vec!["train", "--train", "ds", "--crop", "100", "--out", oj], "--crop"),
        (vec!["train", "--train", "ds", "--occluders", "2", "--out", oj], "--occluders"),
        (vec!["train", "--train", "ds", "--resolution-drop", "NaN", "--out", oj], "--resolution-drop"),
        (vec!["train", "--train", "ds", "--batch", "0", "--out", oj], "--batch"),
        (vec!["templates", "build", "--features", "0", "--out", ot], "--features"),
        (vec!["templates", "build", "--distances", "4:1:0.1", "--out", ot], "--distances"),
        (vec!["templates", "build", "--distances", "1:NaN:0.1", "--out", ot], "--distances"),
        (vec!["templates", "build", "--inplane-step-deg", "NaN", "--out", ot], "--inplane-step-deg"),
        (vec!["demo", "--resolution", "0", "--out", o], "--resolution"),
        (vec!["bench", "--stereo-scenes", "0", "--out", o], "--stereo-scenes"),
        (vec!["calib", "detect", "--threads", "0", img], "--threads"),
        (vec!["locate", "--rig", "rig.json", "--image", img, "--range-m", "4:1", "--out", oj], "--range-m"),
        (vec!["locate", "--rig", "rig.json", "--image", img, "--range-m", "NaN:3", "--out", oj], "--range-m"),
        (vec!["detect", "--image", img, "--range-m", "0:3", "--out", oj], "--range-m"),
        (vec!["train", "--train", "ds", "--range-m", "1", "--out", oj], "--range-m"),
        (vec!["synth", "real", "--split", "val", "--range-m", "5:1", "--out", o], "--range-m"),
        (vec!["synth", "real", "--split", "val", "--tubes", "3:1", "--out", o], "--tubes"),
        (vec!["synth", "real", "--split", "train", "--hfov-deg", "20:10", "--out", o], "--hfov-deg"),
        (vec!["synth", "real", "--split", "train", "--hfov-deg", "0:10", "--out", o], "--hfov-deg"),
        (vec!["synth", "real", "--split", "train", "--hfov-deg", "10", "--out", o], "--hfov-deg"),
    ];
    let mut failures = Vec::new();
    for (args, flag) in &cases {
        let o = tubeloc(args);
        let err = stderr(&o);
        if o.status.code() != Some(2) || !err.contains(flag) {
            failures.push(format!("tubeloc {}: exit {:?}, expected 2 naming {flag}: {err}", args.join(" "), o.status.code()));
        }
        if err.contains("panicked") {
            failures.push(format!("tubeloc {}: panic: {err}", args.join(" ")));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    // Nothing written: only the input image is in the folder (no out, out.json, out.tlt, no
    // temporaries).
    assert_eq!(entries(d), vec!["img_64x64.png"]);
}

#[test]
fn library_size_is_estimated_and_refused_with_the_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("lib.tlt");
    let o = tubeloc(&["templates", "build", "--distances", "1:4:1e-9", "--out", p(&out)]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("3.00e9 distances") && err.contains("templates") && err.contains("GiB") && err.contains("--max-templates"), "{err}");
    // A small library is built, and a limit below it refuses it.
    let ok = tubeloc(&["templates", "build", "--distances", "1:2:1", "--step-deg", "30", "--out", p(&out)]);
    assert!(ok.status.success(), "{}", stderr(&ok));
    assert!(stderr(&ok).contains("estimated peak memory"), "{}", stderr(&ok));
    assert!(out.is_file());
    let small = dir.path().join("small.tlt");
    let o = tubeloc(&["templates", "build", "--distances", "1:2:1", "--step-deg", "30", "--max-templates", "5", "--out", p(&small)]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("above the limit of 5 templates"), "{}", stderr(&o));
    assert!(!small.exists());
}

#[test]
fn calib_detect_on_tiny_images_reports_no_tags_instead_of_crashing() {
    let dir = tempfile::tempdir().unwrap();
    let imgs: Vec<PathBuf> = [(1, 1), (2, 2), (8, 1), (4000, 1), (1, 4000), (3, 3), (4000, 2)].iter().map(|&(w, h)| png(dir.path(), w, h)).collect();
    let mut args = vec!["calib", "detect"];
    args.extend(imgs.iter().map(|i| p(i)));
    for dec in ["1", "1.5", "2", "64"] {
        let mut a = args.clone();
        a.extend(["--decimate", dec]);
        let o = tubeloc(&a);
        assert!(o.status.success(), "decimate {dec}: exit {:?} {}", o.status.code(), stderr(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v.as_object().unwrap().len(), imgs.len());
        assert!(v.as_object().unwrap().values().all(|d| d.as_array().unwrap().is_empty()));
    }
}

#[test]
fn calib_groundtruth_with_a_one_pixel_image_does_not_crash() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    std::fs::create_dir_all(ds.join("images")).unwrap();
    image::GrayImage::new(1, 1).save(ds.join("images/a.png")).unwrap();
    image::GrayImage::new(4000, 2).save(ds.join("images/b.png")).unwrap();
    let cam = serde_json::json!({"width": 1, "height": 1, "fx": 100.0, "fy": 100.0, "cx": 0.0, "cy": 0.0});
    let coco = serde_json::json!({
        "images": [{"id": 1, "file_name": "a.png", "width": 1, "height": 1, "camera": cam}, {"id": 2, "file_name": "b.png", "width": 4000, "height": 2, "camera": cam}],
        "annotations": [], "categories": [{"id": 1, "name": "tube"}]
    });
    std::fs::write(ds.join("annotations.json"), coco.to_string()).unwrap();
    let o = tubeloc(&["calib", "groundtruth", "--dataset", p(&ds)]);
    // No tag in any image: a clear error (exit 1), not a signal.
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("no mount tag found"), "{}", stderr(&o));
}

/// A small COCO ground truth and results for `eval` (bbox IoU).
fn eval_inputs(dir: &Path) -> (PathBuf, PathBuf) {
    let gt = serde_json::json!({
        "images": [{"id": 1, "file_name": "a.png", "width": 20, "height": 20}],
        "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [2.0, 2.0, 6.0, 4.0], "area": 24.0, "iscrowd": 0,
                         "segmentation": [[2.0, 2.0, 8.0, 2.0, 8.0, 6.0, 2.0, 6.0]]}],
        "categories": [{"id": 1, "name": "tube"}]
    });
    let dt = serde_json::json!([{"image_id": 1, "category_id": 1, "bbox": [2.0, 2.0, 6.0, 4.0], "score": 0.9}]);
    let (g, r) = (dir.join("gt.json"), dir.join("dt.json"));
    std::fs::write(&g, gt.to_string()).unwrap();
    std::fs::write(&r, dt.to_string()).unwrap();
    (g, r)
}

/// Runs tubeloc with stdout a pipe whose reader is already closed (EPIPE on every write).
/// (`std::io::pipe` is newer than the workspace's minimum Rust; tests build with the current one.)
#[allow(clippy::incompatible_msrv)]
fn with_closed_stdout(args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    Command::new(env!("CARGO_BIN_EXE_tubeloc")).args(args).stdout(Stdio::from(writer)).stderr(Stdio::piped()).output().expect("running tubeloc")
}

#[test]
fn closed_stdout_is_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let (gt, dt) = eval_inputs(dir.path());
    let out = dir.path().join("eval");
    let o = with_closed_stdout(&["eval", "--gt", p(&gt), "--dt", p(&dt), "--iou-type", "bbox", "--out", p(&out)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    assert!(out.join("metrics.json").is_file(), "metrics.json missing");
    // The same with the output read (a check that the evaluation itself runs).
    let o = tubeloc(&["eval", "--gt", p(&gt), "--dt", p(&dt), "--iou-type", "bbox"]);
    assert!(o.status.success() && String::from_utf8_lossy(&o.stdout).contains("Average Precision"), "{}", stderr(&o));

    let img = png(dir.path(), 32, 32);
    let o = with_closed_stdout(&["calib", "detect", p(&img)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let lib = dir.path().join("lib.tlt");
    let o = tubeloc(&["templates", "build", "--distances", "1:2:1", "--step-deg", "30", "--out", p(&lib)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = with_closed_stdout(&["templates", "info", p(&lib)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
}

#[test]
fn output_through_a_symlink_to_dev_null_keeps_both() {
    let dir = tempfile::tempdir().unwrap();
    let img = png(dir.path(), 32, 32);
    let link = dir.path().join("tags.json");
    std::os::unix::fs::symlink("/dev/null", &link).unwrap();
    let o = tubeloc(&["calib", "detect", p(&img), "--out", p(&link)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
    assert_eq!(entries(dir.path()), vec!["img_32x32.png", "tags.json"]);
}

#[test]
fn synth_removes_temporaries_of_killed_runs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ds");
    let mut child = Command::new("true").spawn().unwrap();
    let dead = child.id();
    child.wait().unwrap();
    let stale = dir.path().join(format!("ds.tmp-{dead}"));
    std::fs::create_dir_all(stale.join("images")).unwrap();
    std::fs::write(stale.join("images/x.png"), b"partial").unwrap();
    let o = tubeloc(&["synth", "--preset", "tiny", "--scenes", "1", "--scale", "0.25", "--resolution", "64", "--out", p(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stale.exists(), "stale temporary left");
    assert_eq!(entries(dir.path()), vec!["ds"]);
}

#[test]
fn train_with_the_same_seed_writes_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    let o = tubeloc(&["synth", "--preset", "tiny", "--scenes", "1", "--scale", "0.25", "--resolution", "64", "--out", p(&ds)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut bytes = Vec::new();
    for name in ["a.safetensors", "b.safetensors"] {
        let out = dir.path().join(name);
        // Separate processes: a HashMap's iteration order differs between them.
        let o = tubeloc(&["train", "--train", p(&ds), "--out", p(&out), "--steps", "2", "--crop", "64", "--batch", "2", "--width", "4", "--seed", "5", "--val-every", "100", "--ckpt-every", "100"]);
        assert!(o.status.success(), "{}", stderr(&o));
        bytes.push(std::fs::read(&out).unwrap());
    }
    assert!(bytes[0] == bytes[1], "same seed, different bytes");
}

/// A missing input file is named once with the system's reason once, whichever reader meets
/// it (rig, template library, model).
#[test]
fn a_missing_file_is_reported_once() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let img = png(d, 64, 64);
    let missing = d.join("missing.json");
    let out = d.join("p.json");
    // (arguments, how often the system's reason appears: the model's own message has none).
    let cases: [(Vec<&str>, usize); 3] = [
        (vec!["locate", "--rig", p(&missing), "--image", p(&img), "--out", p(&out)], 1),
        (vec!["detect", "--method", "line2d", "--image", p(&img), "--templates", p(&missing), "--out", p(&out)], 1),
        (vec!["detect", "--method", "learned", "--image", p(&img), "--model", p(&missing), "--out", p(&out)], 0),
    ];
    for (args, reasons) in cases {
        let o = tubeloc(&args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?}");
        assert!(err.contains("missing.json"), "{args:?}: {err}");
        assert_eq!(err.matches("No such file or directory").count(), reasons, "{args:?}: {err}");
        assert!(!out.exists());
    }
}

/// A JPEG cut short (a partial download) decodes to an image with blank rows, so every
/// command that reads images refuses it, naming the file and saying it is truncated, and
/// writes nothing.
#[test]
fn a_truncated_jpeg_is_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let full = d.join("whole.jpg");
    image::RgbImage::from_fn(320, 240, |x, y| image::Rgb([(x % 256) as u8, (y % 256) as u8, ((x * y) % 256) as u8])).save(&full).unwrap();
    let bytes = std::fs::read(&full).unwrap();
    let cut = d.join("cut.jpg");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let cam = serde_json::json!({"width": 320, "height": 240, "fx": 300.0, "fy": 300.0, "cx": 159.5, "cy": 119.5});
    let rig = serde_json::json!({"cameras": [{"name": "C", "model": cam, "T_rig_cam": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0, 0, 0]}}], "stereo_pairs": []});
    std::fs::write(d.join("rig.json"), rig.to_string()).unwrap();
    let out = d.join("out.json");
    let rig_path = d.join("rig.json");
    let (c, r, o) = (p(&cut), p(&rig_path), p(&out));
    for args in [vec!["detect", "--method", "learned", "--image", c, "--out", o], vec!["locate", "--rig", r, "--image", c, "--out", o], vec!["calib", "detect", c, "--out", o]] {
        let run = tubeloc(&args);
        let err = stderr(&run);
        assert!(!run.status.success(), "{args:?}");
        assert!(err.contains("cut.jpg") && err.contains("truncated"), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    // The whole file is read.
    ok(&["calib", "detect", p(&full), "--out", o]);
}

/// A camera of another image size gives a wrong working scale and ground, silently: `detect`
/// refuses it naming both sizes, as `locate` does, and writes nothing; a camera model is
/// also a mono rig for `locate`.
#[test]
fn a_camera_of_another_size_is_refused_and_a_camera_is_a_mono_rig() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let img = png(d, 64, 48);
    let cam = |w: u32, h: u32| serde_json::json!({"width": w, "height": h, "fx": 60.0, "fy": 60.0, "cx": w as f64 / 2.0 - 0.5, "cy": h as f64 / 2.0 - 0.5}).to_string();
    let (wrong, right) = (d.join("wrong.json"), d.join("right.json"));
    std::fs::write(&wrong, cam(100, 80)).unwrap();
    std::fs::write(&right, cam(64, 48)).unwrap();
    let out = d.join("out.json");
    for method in ["learned", "line2d"] {
        let run = tubeloc(&["detect", "--method", method, "--image", p(&img), "--camera", p(&wrong), "--out", p(&out)]);
        let err = stderr(&run);
        assert!(!run.status.success(), "{method}");
        assert!(err.contains("img_64x48.png is 64x48 px") && err.contains("wrong.json describes 100x80 px"), "{method}: {err}");
        assert!(!out.exists());
    }
    let run = tubeloc(&["locate", "--rig", p(&wrong), "--image", p(&img), "--out", p(&out)]);
    assert!(!run.status.success() && stderr(&run).contains("64x48") && stderr(&run).contains("100x80"), "{}", stderr(&run));
    assert!(!out.exists());
    ok(&["detect", "--method", "learned", "--image", p(&img), "--camera", p(&right), "--out", p(&out)]);
    std::fs::remove_file(&out).unwrap();
    let run = tubeloc(&["locate", "--rig", p(&right), "--image", p(&img), "--out", p(&out)]);
    assert!(out.exists(), "{}", stderr(&run));
    let doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(doc["camera"], "camera");
}

/// A dataset image whose camera does not parse or is of another size: `detect` names the
/// image and the problem, for both detectors, instead of detecting it at scale 1.
#[test]
fn a_dataset_images_bad_camera_is_refused_naming_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("images")).unwrap();
    let img = png(&d.join("images"), 64, 48);
    let name = img.file_name().unwrap().to_str().unwrap().to_string();
    let cam = |w: u32, h: u32| serde_json::json!({"width": w, "height": h, "fx": 60.0, "fy": 60.0, "cx": 31.5, "cy": 23.5});
    let mut broken = cam(64, 48);
    broken.as_object_mut().unwrap().remove("fy");
    let out = d.join("out.json");
    for (camera, says) in [(broken, "camera"), (cam(100, 80), "is 64x48 px but its camera describes 100x80 px images")] {
        let ds = serde_json::json!({"images": [{"id": 7, "width": 64, "height": 48, "file_name": name, "camera": camera}], "annotations": [], "categories": [{"id": 1, "name": "tube"}]});
        std::fs::write(d.join("annotations.json"), ds.to_string()).unwrap();
        for method in ["learned", "line2d"] {
            let run = tubeloc(&["detect", "--method", method, "--dataset", p(d), "--out", p(&out)]);
            let err = stderr(&run);
            assert!(!run.status.success(), "{method}");
            assert!(err.contains(&format!("image 7 ({name})")) && err.contains(says), "{method}: {err}");
            assert!(!out.exists());
        }
    }
    let ds = serde_json::json!({"images": [{"id": 7, "width": 64, "height": 48, "file_name": name, "camera": cam(64, 48)}], "annotations": [], "categories": [{"id": 1, "name": "tube"}]});
    std::fs::write(d.join("annotations.json"), ds.to_string()).unwrap();
    ok(&["detect", "--method", "learned", "--dataset", p(d), "--out", p(&out)]);
}
