//! Helpers shared by the CLI test files: run the `tubeloc` binary and read its output.
#![allow(dead_code)] // each test file uses a part

use std::path::Path;
use std::process::{Command, Output};

/// Runs `tubeloc` with `args`, capturing its output.
pub fn tubeloc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tubeloc")).args(args).output().expect("running tubeloc")
}

/// Runs `tubeloc` and asserts it succeeded (the message quotes its stderr).
pub fn ok(args: &[&str]) -> Output {
    let o = tubeloc(args);
    assert!(o.status.success(), "tubeloc {} failed: {}", args.join(" "), String::from_utf8_lossy(&o.stderr));
    o
}

/// The run's stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A path as a command-line argument.
pub fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A PDS3 product of an RGB8 image whose camera is the CAHV model of the pinhole `cam`
/// (`fx fy cx cy`) at `centre` with axes `r_rover_cam` (columns: x right, y down, z forward)
/// in a rover frame (z down): the label at the head, the samples from record 4. `fisheye`,
/// when not empty, is `MODEL_COMPONENT_5` to `_9` of a CAHVORE model with that CAHV part.
pub fn pds3_product(path: &Path, rgb: &image::RgbImage, cam: &serde_json::Value, r_rover_cam: &nalgebra::Matrix3<f64>, centre: &nalgebra::Vector3<f64>, fisheye: &str) {
    let f = |k: &str| cam[k].as_f64().unwrap();
    let (a, x, y) = (r_rover_cam.column(2).into_owned(), r_rover_cam.column(0).into_owned(), r_rover_cam.column(1).into_owned());
    let (h, v) = (f("fx") * x + f("cx") * a, f("fy") * y + f("cy") * a);
    let t = |w: &nalgebra::Vector3<f64>| format!("({:.17e},{:.17e},{:.17e})", w.x, w.y, w.z);
    let model_type = if fisheye.is_empty() { "CAHV" } else { "CAHVORE" };
    let label = format!(
        "PDS_VERSION_ID = PDS3\nRECORD_TYPE = FIXED_LENGTH\nRECORD_BYTES = 1024\n^IMAGE = 4\nPRODUCT_ID = \"{}\"\n\
GROUP = GEOMETRIC_CAMERA_MODEL_PARMS\n  MODEL_TYPE = {model_type}\n  MODEL_COMPONENT_1 = {}\n  MODEL_COMPONENT_2 = {}\n\
  MODEL_COMPONENT_3 = {}\n  MODEL_COMPONENT_4 = {}\n{fisheye}  REFERENCE_COORD_SYSTEM_NAME = \"ROVER_NAV_FRAME\"\n\
END_GROUP = GEOMETRIC_CAMERA_MODEL_PARMS\nOBJECT = IMAGE\n  LINES = {}\n  LINE_SAMPLES = {}\n  BANDS = 3\n\
  SAMPLE_TYPE = UNSIGNED_INTEGER\n  SAMPLE_BITS = 8\n  BAND_STORAGE_TYPE = SAMPLE_INTERLEAVED\nEND_OBJECT = IMAGE\nEND\n",
        path.file_stem().unwrap().to_str().unwrap(),
        t(centre),
        t(&a),
        t(&h),
        t(&v),
        rgb.height(),
        rgb.width()
    );
    let mut bytes = label.into_bytes();
    assert!(bytes.len() <= 3 * 1024);
    bytes.resize(3 * 1024, b' ');
    bytes.extend_from_slice(rgb.as_raw());
    std::fs::write(path, bytes).unwrap();
}

/// The COCO results list of a detections file.
pub fn detections(path: &Path) -> Vec<serde_json::Value> {
    serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(path).unwrap()).unwrap().as_array().unwrap().clone()
}

/// A detection's mask (its `segmentation`).
pub fn mask(v: &serde_json::Value) -> tubeloc_core::Rle {
    let size = &v["segmentation"]["size"];
    let (h, w) = (size[0].as_u64().unwrap() as u32, size[1].as_u64().unwrap() as u32);
    let seg: tubeloc_core::Segmentation = serde_json::from_value(v["segmentation"].clone()).unwrap();
    seg.to_rle(h, w).unwrap()
}

/// The IoU of two masks.
pub fn iou(a: &tubeloc_core::Rle, b: &tubeloc_core::Rle) -> f64 {
    tubeloc_core::Rle::iou(std::slice::from_ref(a), std::slice::from_ref(b), &[false])[0]
}

/// A detection's score.
pub fn score(v: &serde_json::Value) -> f64 {
    v["score"].as_f64().unwrap()
}

/// The shared real rover data, `../shared/data/real_mars` beside the repository; a test that
/// needs it fails naming the missing folder.
pub fn real_data() -> std::path::PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real_mars");
    assert!(d.join("MANIFEST.tsv").exists(), "{} is missing: this test needs ../shared/data beside the repository", d.display());
    d
}

/// Three composites on real grey Navcam frames of the validation sols (each frame's own camera
/// and ground; `tubeloc synth real --split val --kind grey --limit 3 --seed 3`) in `dir/set`,
/// and the default template library in `dir/default.tlt`. Needs `../shared/data/real_mars`
/// beside the repository.
pub fn real_grey_val_set_and_library(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let real = real_data();
    let set = dir.join("set");
    ok(&["synth", "real", "--data", p(&real), "--split", "val", "--kind", "grey", "--per-view", "1", "--limit", "3", "--seed", "3", "--out", p(&set)]);
    let lib = dir.join("default.tlt");
    ok(&["templates", "build", "--out", p(&lib)]);
    (set, lib)
}
