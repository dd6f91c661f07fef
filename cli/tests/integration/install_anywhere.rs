//! A copied `tubeloc` runs with no way back to the source tree: its working directory is a
//! fresh temporary folder, its environment is empty but for `HOME` (that folder) and `PATH`,
//! and the binary names no path of the workspace that built it. The demo uses the shipped
//! learned model (embedded) and `locate` uses the model's shipped score calibration.

use crate::common;

use common::*;
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output};

/// Runs the copied binary in `dir` with an environment that knows nothing of the build.
fn run_copied(bin: &Path, dir: &Path, args: &[&str]) -> Output {
    Command::new(bin).args(args).current_dir(dir).env_clear().env("HOME", dir).env("PATH", "/usr/bin:/bin").output().expect("running the copied tubeloc")
}

#[test]
fn a_copied_binary_runs_the_demo_and_locate_from_an_empty_folder() {
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("tubeloc");
    std::fs::copy(env!("CARGO_BIN_EXE_tubeloc"), &bin).unwrap();
    // The binary holds no path into the workspace that built it (the old lookup of the model
    // went through `CARGO_MANIFEST_DIR/../data`).
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_str().unwrap().to_string();
    let bytes = std::fs::read(&bin).unwrap();
    assert!(!bytes.windows(workspace.len()).any(|w| w == workspace.as_bytes()), "the binary names the workspace {workspace}");

    let o = run_copied(&bin, dir.path(), &["demo", "--out", "demo-out"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report = std::fs::read_to_string(dir.path().join("demo-out/report.md")).unwrap();
    assert!(report.lines().any(|l| l.starts_with("| learned |")), "the demo ran the shipped learned model: {report}");

    // `locate` on an image the demo wrote, with its rig, at the defaults.
    let gt: Value = serde_json::from_str(&std::fs::read_to_string(dir.path().join("demo-out/dataset/annotations.json")).unwrap()).unwrap();
    let image = format!("demo-out/dataset/images/{}", gt["images"][0]["file_name"].as_str().unwrap());
    let o = run_copied(&bin, dir.path(), &["locate", "--rig", "demo-out/rig.json", "--image", &image, "--out", "poses.json"]);
    assert!(matches!(o.status.code(), Some(0 | 3)), "{}", stderr(&o));
    assert!(!stderr(&o).contains("no score calibration"), "{}", stderr(&o));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(dir.path().join("poses.json")).unwrap()).unwrap();
    assert_eq!(doc["detector"], "learned");
    let shipped: Value = serde_json::from_str(&std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/models/tubenet.calibration.json")).unwrap()).unwrap();
    assert_eq!(doc["min_probability"], shipped["threshold"], "the shipped calibration's threshold");
}
