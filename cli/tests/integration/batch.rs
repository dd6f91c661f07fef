//! `tubeloc locate --images` (batch runs) and `tubeloc locate merge`: two shards merged give
//! the unsharded run's files byte for byte; a killed shard resumes from its finished frames;
//! merge refuses missing and overlapping shards; a bad frame is recorded and the others go on;
//! bad shards are bad command lines.

use crate::common;

use common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// A rendered tiny dataset (every crop the same size) and a one-camera rig of its first image.
fn rendered_frames(dir: &Path) -> (PathBuf, PathBuf) {
    let ds = dir.join("dataset");
    ok(&["synth", "--preset", "tiny", "--scenes", "2", "--scale", "0.25", "--resolution", "256", "--seed", "7", "--out", p(&ds)]);
    let gt: Value = serde_json::from_str(&std::fs::read_to_string(ds.join("annotations.json")).unwrap()).unwrap();
    let rig = serde_json::json!({"cameras": [{"name": "C", "model": gt["images"][0]["camera"], "T_rig_cam": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0, 0, 0]}}], "stereo_pairs": []});
    let rig_path = dir.join("rig.json");
    std::fs::write(&rig_path, rig.to_string()).unwrap();
    (rig_path, ds.join("images"))
}

/// `tubeloc locate --images` with extra words; asserts a finished run (0, or 3: no tube).
fn batch(rig: &Path, images: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["locate", "--rig", p(rig), "--images", p(images), "--out", p(out)];
    args.extend_from_slice(extra);
    let o = tubeloc(&args);
    assert!(matches!(o.status.code(), Some(0 | 3)), "{}", stderr(&o));
    o
}

/// The files of `dir/frames`, by name.
fn frame_files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir.join("frames")).unwrap().map(|e| e.unwrap()).map(|e| (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap())).collect();
    v.sort();
    v
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn sharded_batch_merges_to_the_unsharded_run_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let (rig, images) = rendered_frames(dir.path());
    let n_images = std::fs::read_dir(&images).unwrap().count();
    assert!(n_images >= 3, "{n_images} frames");

    let all = dir.path().join("all");
    batch(&rig, &images, &all, &["--overlays"]);
    let (s0, s1) = (dir.path().join("shard0"), dir.path().join("shard1"));
    batch(&rig, &images, &s0, &["--overlays", "--shard", "0/2"]);
    batch(&rig, &images, &s1, &["--overlays", "--shard", "1/2"]);

    // Frame k of the sorted list is in shard k mod 2.
    let summary = json(&all.join("summary.json"));
    let frames = summary["frames"].as_array().unwrap();
    assert_eq!(frames.len(), n_images);
    assert_eq!(json(&s0.join("summary.json"))["frames"].as_array().unwrap().iter().map(|f| f["frame"].as_u64().unwrap()).collect::<Vec<_>>(), (0..n_images as u64).step_by(2).collect::<Vec<_>>());
    let mut names: Vec<String> = std::fs::read_dir(&images).unwrap().map(|e| e.unwrap().path().display().to_string()).collect();
    names.sort();
    assert_eq!(frames.iter().map(|f| f["image"].as_str().unwrap().to_string()).collect::<Vec<_>>(), names);
    // One document per frame, in the one-image schema, without timings.
    let doc = json(&all.join(frames[0]["result"].as_str().unwrap()));
    assert_eq!(doc["schema"], "tubeloc.locate.v1");
    assert_eq!(doc["detector"], "learned");
    assert!(doc.get("run").is_none(), "a batch frame's document carries no timings");
    assert_eq!(frames[0]["located"].as_u64().unwrap() as usize, doc["tubes"].as_array().unwrap().iter().filter(|t| t["status"] == "located").count());

    let merged = dir.path().join("merged");
    let o = ok(&["locate", "merge", p(&s0), p(&s1), "--out", p(&merged)]);
    assert!(String::from_utf8_lossy(&o.stdout).contains(&format!("{n_images} frames from 2 folder(s)")), "{}", String::from_utf8_lossy(&o.stdout));
    assert_eq!(frame_files(&merged), frame_files(&all), "merged frame files are the unsharded run's, byte for byte");
    assert_eq!(frame_files(&all).len(), 2 * n_images, "a document and an overlay per frame");
    assert_eq!(std::fs::read(merged.join("summary.json")).unwrap(), std::fs::read(all.join("summary.json")).unwrap());
    assert_eq!(json(&merged.join("run.json"))["runs"].as_array().unwrap().len(), 2, "both shards' runs");

    // A shard killed after some frames: the finished ones are skipped when it runs again.
    let before = frame_files(&s0);
    let first = json(&s0.join("summary.json"))["frames"][0]["result"].as_str().unwrap().to_string();
    std::fs::remove_file(s0.join(&first)).unwrap();
    std::fs::remove_file(s0.join("summary.json")).unwrap();
    let o = tubeloc(&["locate", "merge", p(&s0), p(&s1), "--out", p(&merged)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("shard0: no summary.json") && stderr(&o).contains("resume"), "{}", stderr(&o));
    batch(&rig, &images, &s0, &["--overlays", "--shard", "0/2"]);
    assert_eq!(frame_files(&s0), before);
    let runs = json(&s0.join("run.json"));
    let last = runs["runs"].as_array().unwrap().last().unwrap().clone();
    assert_eq!((last["frames_processed"].as_u64(), last["frames_skipped"].as_u64()), (Some(1), Some(n_images.div_ceil(2) as u64 - 1)), "{last}");

    // Missing and overlapping shards are refused.
    let o = tubeloc(&["locate", "merge", p(&s0), "--out", p(&dir.path().join("m2"))]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("missing shard(s): 1/2"), "{}", stderr(&o));
    let o = tubeloc(&["locate", "merge", p(&s0), p(&s1), p(&s0), "--out", p(&dir.path().join("m3"))]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("is in both") && stderr(&o).contains("overlap"), "{}", stderr(&o));
    // A folder from another list.
    let few = dir.path().join("few");
    std::fs::create_dir(&few).unwrap();
    std::fs::copy(&names[0], few.join("a.png")).unwrap();
    let other = dir.path().join("other");
    batch(&rig, &few, &other, &[]);
    let o = tubeloc(&["locate", "merge", p(&s0), p(&other), "--out", p(&dir.path().join("m4"))]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("another frame list"), "{}", stderr(&o));
}

#[test]
fn a_bad_frame_is_recorded_and_the_others_are_located() {
    let dir = tempfile::tempdir().unwrap();
    let (rig, images) = rendered_frames(dir.path());
    let first = std::fs::read_dir(&images).unwrap().next().unwrap().unwrap().path();
    let list = dir.path().join("frames.txt");
    std::fs::write(&list, format!("# two frames\n{}\nbroken.png\n", first.display())).unwrap();
    std::fs::write(dir.path().join("broken.png"), b"not a png").unwrap();
    let out = dir.path().join("out");
    let o = tubeloc(&["locate", "--rig", p(&rig), "--images", p(&list), "--out", p(&out)]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("1 of 2 frame(s) failed"), "{}", stderr(&o));
    let summary = json(&out.join("summary.json"));
    assert_eq!(summary["failed"], 1);
    let bad = &summary["frames"][0];
    assert!(bad["image"].as_str().unwrap().ends_with("broken.png") && bad["error"].as_str().unwrap().contains("broken.png"), "{summary}");
    assert!(bad.get("result").is_none());
    assert!(out.join(summary["frames"][1]["result"].as_str().unwrap()).exists());
}

#[test]
fn shards_and_batch_flags_are_checked_on_the_command_line() {
    for shard in ["3/2", "0/0", "2", "1/x"] {
        let o = tubeloc(&["locate", "--rig", "r.json", "--images", "frames/", "--out", "o", "--shard", shard]);
        assert_eq!(o.status.code(), Some(2), "--shard {shard}: {}", stderr(&o));
        assert!(stderr(&o).contains("--shard"), "{}", stderr(&o));
    }
    let o = tubeloc(&["locate", "--rig", "r.json", "--image", "a.png", "--images", "frames/", "--out", "o"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let o = tubeloc(&["locate", "--rig", "r.json", "--image", "a.png", "--shard", "0/2", "--out", "o"]);
    assert_eq!(o.status.code(), Some(2), "--shard needs --images: {}", stderr(&o));
    let o = tubeloc(&["locate", "--rig", "r.json", "--image", "a.png", "--overlays", "--out", "o"]);
    assert_eq!(o.status.code(), Some(2), "--overlays needs --images: {}", stderr(&o));
    assert!(stderr(&o).contains("--overlays is for batch runs (--images"), "{}", stderr(&o));
    let o = tubeloc(&["locate", "merge", "--out", "o"]);
    assert_eq!(o.status.code(), Some(2), "merge needs folders: {}", stderr(&o));
}
