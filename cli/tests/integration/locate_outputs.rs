//! `tubeloc locate`'s outputs and refusals: one JSON document and the overlay, written before
//! anything is printed (a closed stdout is not an error); no file from a failed run; masks of
//! the wrong size refused; external results selected by the image's file name; a bad --ground
//! refused as a bad command line before any work; no tube handed over from an underexposed
//! frame.

use crate::common;

use common::*;
use nalgebra::Vector3;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use tubeloc_core::{CameraModel, Segmentation, TubeAxisPose};
use tubeloc_refine::silhouette::silhouette_mask;
use tubeloc_refine::CylinderModel;

/// A painted 320x240 scene with one tube, a one-camera rig and COCO results holding the tube's
/// mask, in a temporary folder; `out` (empty) for the outputs.
struct Painted {
    dir: tempfile::TempDir,
    mask_seg: Value,
}

impl Painted {
    fn new() -> Painted {
        Painted::with_levels(210, 60, 23)
    }
    /// The scene with the tube at grey level `tube` on ground of `ground` plus a texture of
    /// `texture` levels.
    fn with_levels(tube: u8, ground: u8, texture: u32) -> Painted {
        let dir = tempfile::tempdir().unwrap();
        let cam = CameraModel::from_hfov(320, 240, 60.0);
        let truth = TubeAxisPose::new(0, 1.0, Vector3::new(0.0, 0.0, 0.6), Vector3::new(1.0, 0.0, 0.1), 0.5).unwrap();
        let model = CylinderModel::new(&tubeloc_core::TubeModel::default()).unwrap();
        let mask = silhouette_mask(&model, &truth, &cam);
        image::GrayImage::from_fn(320, 240, |x, y| image::Luma([if mask.get(x as usize, y as usize) { tube } else { ground + ((x + 2 * y) % texture) as u8 }])).save(dir.path().join("img.png")).unwrap();
        let rig = json!({"cameras": [{"name": "C", "model": cam, "T_rig_cam": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0, 0, 0]}}], "stereo_pairs": []});
        std::fs::write(dir.path().join("rig.json"), rig.to_string()).unwrap();
        std::fs::create_dir(dir.path().join("out")).unwrap();
        let mask_seg = serde_json::to_value(Segmentation::from_rle(&tubeloc_core::Rle::from_mask(&mask))).unwrap();
        Painted { dir, mask_seg }
    }
    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
    fn results(&self, entries: Value) -> PathBuf {
        let path = self.path("results.json");
        std::fs::write(&path, entries.to_string()).unwrap();
        path
    }
    fn entry(&self, image_id: u64) -> Value {
        json!({"image_id": image_id, "category_id": 1, "score": 0.9, "segmentation": self.mask_seg})
    }
    fn locate_args(&self, results: &Path) -> Vec<String> {
        ["locate", "--rig", p(&self.path("rig.json")), "--image", p(&self.path("img.png")), "--detector", "external", "--results", p(results), "--out", p(&self.path("out/poses.json"))].iter().map(|s| s.to_string()).collect()
    }
    fn outputs(&self) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(self.path("out")).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    }
}

fn run(args: &[String]) -> Output {
    tubeloc(&args.iter().map(String::as_str).collect::<Vec<_>>())
}

#[test]
fn locate_writes_one_document_and_the_overlay_and_survives_a_closed_stdout() {
    let s = Painted::new();
    let results = s.results(json!([s.entry(7)]));
    // stdout is a pipe whose reading end is closed before the program prints.
    let mut child = Command::new(env!("CARGO_BIN_EXE_tubeloc")).args(s.locate_args(&results)).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    assert_eq!(s.outputs(), ["poses.json", "poses.overlay.png"]);
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(s.path("out/poses.json")).unwrap()).unwrap();
    assert_eq!(doc["schema"], "tubeloc.locate.v1");
    assert_eq!(doc["tubes"].as_array().unwrap().len(), 1);
    assert_eq!(doc["tubes"][0]["converged"], true);
    assert_eq!(doc["detections"].as_array().unwrap().len(), 1, "the detections are embedded");
    assert_eq!(doc["camera_model"]["width"], 320);
}

#[test]
fn a_failing_locate_leaves_no_file() {
    let s = Painted::new();
    let results = s.results(json!([s.entry(7)]));
    // Fails after detection and refinement: the stereo pair is missing.
    let mut a = s.locate_args(&results);
    a.extend(["--right".to_string(), p(&s.path("img.png")).to_string()]);
    let o = run(&a);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(s.outputs().is_empty(), "{:?}", s.outputs());
    // Fails at the last write (--out is a folder): the overlay written before it is removed.
    std::fs::create_dir(s.path("out/poses.json")).unwrap();
    let o = run(&s.locate_args(&results));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("poses.json"), "{}", stderr(&o));
    assert_eq!(s.outputs(), ["poses.json"], "only the folder that was there");
    assert!(std::fs::read_dir(s.path("out/poses.json")).unwrap().next().is_none());
}

#[test]
fn masks_of_another_size_are_refused_naming_the_file_and_the_detection() {
    let s = Painted::new();
    let small = serde_json::to_value(Segmentation::from_rle(&tubeloc_core::Rle::from_mask(&tubeloc_core::BinaryMask::new(100, 80)))).unwrap();
    let results = s.results(json!([s.entry(7), {"image_id": 7, "category_id": 1, "score": 0.5, "bbox": [1.0, 1.0, 10.0, 4.0], "segmentation": small}]));
    let o = run(&s.locate_args(&results));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("results.json") && e.contains("detection 1") && e.contains("100x80") && e.contains("320x240"), "{e}");
    assert!(s.outputs().is_empty());
}

#[test]
fn external_results_are_selected_by_the_images_file_name() {
    let s = Painted::new();
    // Results for two images cannot be told apart without names.
    let mut other = s.entry(6);
    other["bbox"] = json!([0.0, 0.0, 5.0, 5.0]);
    other.as_object_mut().unwrap().remove("segmentation");
    let results = s.results(json!([s.entry(5), other]));
    let o = run(&s.locate_args(&results));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("2 images") && stderr(&o).contains("--results-images"), "{}", stderr(&o));
    assert!(s.outputs().is_empty());

    // With the image list, only image 5's results are used.
    let names = json!({"images": [{"id": 5, "file_name": "images/img.png", "width": 320, "height": 240}, {"id": 6, "file_name": "images/other.png", "width": 320, "height": 240}], "annotations": [], "categories": [{"id": 1, "name": "tube"}]});
    std::fs::write(s.path("names.json"), names.to_string()).unwrap();
    let mut a = s.locate_args(&results);
    a.extend(["--results-images".to_string(), p(&s.path("names.json")).to_string()]);
    let o = run(&a);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(s.path("out/poses.json")).unwrap()).unwrap();
    let ids: Vec<u64> = doc["detections"].as_array().unwrap().iter().map(|d| d["image_id"].as_u64().unwrap()).collect();
    assert_eq!(ids, [5]);

    // Entries that name their file.
    let mut mine = s.entry(1);
    mine["file_name"] = json!("img.png");
    let mut theirs = s.entry(2);
    theirs["file_name"] = json!("other.png");
    let results = s.results(json!([theirs, mine]));
    let o = run(&s.locate_args(&results));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(s.path("out/poses.json")).unwrap()).unwrap();
    assert_eq!(doc["detections"].as_array().unwrap().len(), 1);
    assert_eq!(doc["detections"][0]["image_id"], 1);
    let mut none = s.entry(1);
    none["file_name"] = json!("elsewhere.png");
    let results = s.results(json!([none]));
    let o = run(&s.locate_args(&results));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("img.png"), "{}", stderr(&o));
}

#[test]
fn a_bad_ground_is_a_bad_command_line_and_writes_nothing() {
    let s = Painted::new();
    let results = s.results(json!([s.entry(7)]));
    for g in ["NaN,-1,0,1", "0,0,0,1", "0,-1,0", "0,-1,0,1,5", "0,-1,x,1"] {
        let mut a = s.locate_args(&results);
        a.extend(["--ground".to_string(), g.to_string()]);
        let o = run(&a);
        assert_eq!(o.status.code(), Some(2), "{g}: {}", stderr(&o));
        assert!(stderr(&o).contains(&format!("{g:?}")), "{g}: the whole argument is quoted: {}", stderr(&o));
        assert!(s.outputs().is_empty());
        // The same for refine.
        let o = tubeloc(&["refine", "--image", p(&s.path("img.png")), "--camera", "c.json", "--detections", p(&results), "--ground", g, "--out", p(&s.path("out/r.json"))]);
        assert_eq!(o.status.code(), Some(2), "refine {g}: {}", stderr(&o));
        assert!(s.outputs().is_empty());
    }
    // A good ground is normalized: "0,-2,0,-3" is the plane y = 1.5 (n = -y up).
    let mut a = s.locate_args(&results);
    a.extend(["--ground".to_string(), "0,-2,0,-3".to_string()]);
    let o = run(&a);
    assert!(matches!(o.status.code(), Some(0) | Some(3)), "{}", stderr(&o));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(s.path("out/poses.json")).unwrap()).unwrap();
    assert_eq!(doc["up_cam"], json!([0.0, -1.0, 0.0]));
}

#[test]
fn no_tube_is_handed_over_from_an_underexposed_frame() {
    // The painted scene at a fifth of its brightness (tube 42, ground 12-15): the fit
    // converges, but the frame's highlights lie at grey level 15 < 48, so the tube is listed
    // as `underexposed` and the run says why; with --min-highlight-level 0 it is located.
    let s = Painted::with_levels(42, 12, 4);
    let results = s.results(json!([s.entry(7)]));
    let o = run(&s.locate_args(&results));
    assert_eq!(o.status.code(), Some(3), "no tube located: {}", stderr(&o));
    assert!(stderr(&o).contains("img.png is underexposed (its highlights lie at grey level 15 < 48)"), "{}", stderr(&o));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(s.path("out/poses.json")).unwrap()).unwrap();
    assert_eq!((doc["tubes"][0]["status"].as_str(), doc["tubes"][0]["converged"].as_bool()), (Some("underexposed"), Some(true)));
    let mut a = s.locate_args(&results);
    a.extend(["--min-highlight-level".to_string(), "0".to_string()]);
    let o = run(&a);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(s.path("out/poses.json")).unwrap()).unwrap();
    assert_eq!(doc["tubes"][0]["status"], "located");
    let o = run(&[&a[..a.len() - 1], &["300".to_string()]].concat());
    assert!(o.status.code() == Some(2) && stderr(&o).contains("grey level in [0, 255]"), "{}", stderr(&o));
    // `detect` says so too, for either detector; the well-exposed scene gives no warning.
    let bright = Painted::new();
    let cam = s.path("camera.json");
    std::fs::write(&cam, serde_json::to_string(&CameraModel::from_hfov(320, 240, 60.0)).unwrap()).unwrap();
    let lib = s.path("coarse.tlt");
    ok(&["templates", "build", "--camera", p(&cam), "--step-deg", "30", "--distances", "0.6:0.8:0.2", "--inplane-range-deg", "0", "--out", p(&lib)]);
    for (scene, dark) in [(&s, true), (&bright, false)] {
        let (img, out) = (scene.path("img.png"), scene.path("d.json"));
        for method in [vec!["--method", "learned"], vec!["--method", "line2d", "--templates", p(&lib)]] {
            let mut args = vec!["detect", "--camera", p(&cam), "--image", p(&img), "--out", p(&out)];
            args.extend(&method);
            let o = tubeloc(&args);
            assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
            let warned = stderr(&o).contains("img.png: underexposed (its highlights lie at grey level 15 < 48)");
            assert_eq!(warned, dark, "{method:?}: {}", stderr(&o));
        }
    }
}
