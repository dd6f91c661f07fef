//! End-to-end tests of the `tubeloc` program: exit codes, error messages, `locate` on a rendered
//! scene (checked against the renderer's exact poses) and `bench` resuming an interrupted run.

use crate::common;

use common::*;
use serde_json::Value;
use std::path::Path;

/// A rendered tiny dataset, its first image's camera as a one-camera rig, and a small library.
struct Scene {
    dir: tempfile::TempDir,
    gt: Value,
}

impl Scene {
    fn new(scenes: &str, resolution: &str) -> Scene {
        let dir = tempfile::tempdir().unwrap();
        let ds = dir.path().join("dataset");
        ok(&["synth", "--preset", "tiny", "--scenes", scenes, "--scale", "0.25", "--resolution", resolution, "--seed", "7", "--out", p(&ds)]);
        let gt: Value = serde_json::from_str(&std::fs::read_to_string(ds.join("annotations.json")).unwrap()).unwrap();
        let cam = &gt["images"][0]["camera"];
        std::fs::write(dir.path().join("camera.json"), cam.to_string()).unwrap();
        let rig = serde_json::json!({"cameras": [{"name": "C", "model": cam, "T_rig_cam": {"rotation": [[1, 0, 0], [0, 0, 1], [0, -1, 0]], "translation": [0.1, 0.2, 0.3]}}], "stereo_pairs": []});
        std::fs::write(dir.path().join("rig.json"), rig.to_string()).unwrap();
        let lib = dir.path().join("lib.tlt");
        ok(&["templates", "build", "--out", p(&lib), "--camera", p(&dir.path().join("camera.json")), "--distances", "1.0:3.5:0.25", "--step-deg", "12"]);
        Scene { dir, gt }
    }
    fn path(&self, name: &str) -> std::path::PathBuf {
        self.dir.path().join(name)
    }
    fn image(&self, i: usize) -> std::path::PathBuf {
        self.path("dataset/images").join(self.gt["images"][i]["file_name"].as_str().unwrap())
    }
}

fn vec3(v: &Value) -> [f64; 3] {
    [v[0].as_f64().unwrap(), v[1].as_f64().unwrap(), v[2].as_f64().unwrap()]
}

#[test]
fn bad_command_line_exits_2() {
    let o = tubeloc(&["locate", "--image", "x.png"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--rig"), "{}", stderr(&o));
}

#[test]
fn locate_errors_name_the_file_and_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("rig.json");
    std::fs::write(&rig, "{\"cameras\": [").unwrap();
    let img = dir.path().join("img.png");
    image::RgbImage::new(64, 48).save(&img).unwrap();
    let out = dir.path().join("poses.json");
    let o = tubeloc(&["locate", "--rig", p(&rig), "--image", p(&img), "--out", p(&out)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("rig.json"), "{}", stderr(&o));

    // A valid rig whose camera is not the image's size.
    let cam = serde_json::json!({"width": 640, "height": 480, "fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0});
    std::fs::write(&rig, serde_json::json!({"cameras": [{"name": "C", "model": cam, "T_rig_cam": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0, 0, 0]}}], "stereo_pairs": []}).to_string()).unwrap();
    let o = tubeloc(&["locate", "--rig", p(&rig), "--image", p(&img), "--out", p(&out)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("img.png is 64x48 but rig camera \"C\""), "{}", stderr(&o));

    // Line2D with a library that is not there; stereo without a pair.
    image::RgbImage::new(640, 480).save(&img).unwrap();
    let missing = dir.path().join("missing.tlt");
    let o = tubeloc(&["locate", "--rig", p(&rig), "--image", p(&img), "--detector", "line2d", "--templates", p(&missing), "--out", p(&out)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains(&format!("reading {}", missing.display())), "{}", stderr(&o));
    let o = tubeloc(&["locate", "--rig", p(&rig), "--image", p(&img), "--right", p(&img), "--out", p(&out)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("no stereo pair"), "{}", stderr(&o));
    assert!(!out.exists(), "a failed run must not leave an output");
}

/// A rover EDR stores 12-bit data in a 16-bit file (PNG or TIFF). Line2D (`detect` and
/// `locate`) and the refiner read it at its real depth, as the learned detector does: the same
/// detections and poses as the 8-bit grey frame (`16 v + 8` maps back to `v` exactly), not a
/// frame divided by 257 into the bottom sixteenth of the range.
#[test]
fn twelve_bit_data_in_a_sixteen_bit_file_give_the_eight_bit_frames_detections_and_poses() {
    let s = Scene::new("1", "512");
    let grey8 = image::open(s.image(0)).unwrap().to_luma8();
    let (eight, twelve, twelve_tiff) = (s.path("grey8.png"), s.path("grey12.png"), s.path("grey12.tif"));
    grey8.save(&eight).unwrap();
    let edr = image::ImageBuffer::<image::Luma<u16>, _>::from_fn(grey8.width(), grey8.height(), |x, y| image::Luma([grey8.get_pixel(x, y).0[0] as u16 * 16 + 8]));
    edr.save(&twelve).unwrap();
    edr.save(&twelve_tiff).unwrap();
    let (lib, cam) = (s.path("lib.tlt"), s.path("camera.json"));
    let detect = |img: &Path, name: &str| -> Value {
        let out = s.path(name);
        ok(&["detect", "--method", "line2d", "--templates", p(&lib), "--camera", p(&cam), "--image", p(img), "--out", p(&out)]);
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap()
    };
    let (a, b) = (detect(&eight, "d8.json"), detect(&twelve, "d12.json"));
    assert!(!a.as_array().unwrap().is_empty(), "Line2D finds the scene's tubes on the 8-bit frame");
    assert_eq!(a, b, "Line2D detections on the 16-bit file");
    assert_eq!(a, detect(&twelve_tiff, "d12t.json"), "Line2D detections on the 16-bit TIFF");
    let locate = |img: &Path, name: &str, detector: &str| -> Value {
        let out = s.path(name);
        let o = tubeloc(&["locate", "--rig", p(&s.path("rig.json")), "--image", p(img), "--detector", detector, "--templates", p(&lib), "--out", p(&out)]);
        assert!(matches!(o.status.code(), Some(0) | Some(3)), "{}", stderr(&o));
        let doc: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        doc["tubes"].clone()
    };
    for detector in ["line2d", "learned"] {
        let (a, b) = (locate(&eight, "p8.json", detector), locate(&twelve, "p12.json", detector));
        assert!(a.as_array().unwrap().iter().any(|t| t["converged"] == true), "{detector}: a tube is located on the 8-bit frame");
        assert_eq!(a, b, "{detector}: located tubes on the 16-bit file");
        assert_eq!(a, locate(&twelve_tiff, "p12t.json", detector), "{detector}: located tubes on the 16-bit TIFF");
    }
}

#[test]
fn locate_finds_tubes_on_a_rendered_scene_with_grasp_frames() {
    let s = Scene::new("1", "512");
    let out = s.path("out/poses.json");
    // The mast pose is known, so is the ground plane z_world = 0 in the camera frame.
    let t: tubeloc_core::Pose = serde_json::from_value(s.gt["images"][0]["T_world_cam"].clone()).unwrap();
    let (normal, d) = tubeloc_core::geometry::ground_plane_in_camera(&t);
    let n = [normal.x, normal.y, normal.z];
    let ground = format!("{},{},{},{d}", n[0], n[1], n[2]);
    let o = tubeloc(&["locate", "--rig", p(&s.path("rig.json")), "--image", p(&s.image(0)), "--detector", "line2d", "--templates", p(&s.path("lib.tlt")), "--ground", &ground, "--out", p(&out)]);
    let code = o.status.code();
    assert!(code == Some(0) || code == Some(3), "{}", stderr(&o));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(doc["schema"], "tubeloc.locate.v1");
    assert!(s.path("out/poses.overlay.png").exists() && doc["detections"].is_array());
    assert!(!s.path("out/poses.detections.json").exists() && !s.path("out/poses.camera.json").exists(), "no side files");
    let tubes = doc["tubes"].as_array().unwrap();
    let converged: Vec<&Value> = tubes.iter().filter(|t| t["converged"] == true).collect();
    assert_eq!(code == Some(0), !converged.is_empty(), "exit 3 exactly when no tube converged");
    for t in tubes {
        // Grasp frame: +x along the flip-free axis, +z (approach) perpendicular to it and
        // downward (against the ground normal), rig frame = T_rig_cam * camera frame.
        let r = &t["T_cam_grasp"]["rotation"];
        let col = |j: usize| [r[0][j].as_f64().unwrap(), r[1][j].as_f64().unwrap(), r[2][j].as_f64().unwrap()];
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let axis = vec3(&t["axis"]);
        assert!((dot(col(0), axis).abs() - 1.0).abs() < 1e-6);
        assert!(dot(col(2), axis).abs() < 1e-6);
        assert!(dot(col(2), n) <= 1e-9, "approach must not point up: {:?}", col(2));
        let tc = vec3(&t["T_cam_grasp"]["translation"]);
        let tr = vec3(&t["T_rig_grasp"]["translation"]);
        // T_rig_cam: x' = x + 0.1, y' = z + 0.2, z' = -y + 0.3.
        assert!((tr[0] - (tc[0] + 0.1)).abs() < 1e-9 && (tr[1] - (tc[2] + 0.2)).abs() < 1e-9 && (tr[2] - (0.3 - tc[1])).abs() < 1e-9);
    }
    // At least one located tube lies within 50 mm of a rendered tube.
    let id = s.gt["images"][0]["id"].clone();
    let truths: Vec<[f64; 3]> = s.gt["annotations"].as_array().unwrap().iter().filter(|a| a["image_id"] == id).map(|a| vec3(&a["T_cam_tube"]["translation"])).collect();
    let best = converged
        .iter()
        .flat_map(|t| {
            truths.iter().map(move |g| {
                let c = vec3(&t["centre"]);
                ((c[0] - g[0]).powi(2) + (c[1] - g[1]).powi(2) + (c[2] - g[2]).powi(2)).sqrt()
            })
        })
        .fold(f64::INFINITY, f64::min);
    assert!(best < 0.05, "nearest located tube is {:.1} mm from a rendered one", best * 1e3);
}

#[test]
fn bench_runs_on_a_tiny_dataset_and_resumes() {
    let s = Scene::new("2", "384");
    let out = s.path("bench");
    let (ds, lib) = (s.path("dataset"), s.path("lib.tlt"));
    let args = ["bench", "--dataset", p(&ds), "--templates", p(&lib), "--skip", "learned,poses,stereo,fullres,tags,real", "--out", p(&out)];
    ok(&args);
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("Table I: Line2D"), "{report}");
    for split in ["no-tags", "with-tags"] {
        let row = report.lines().find(|l| l.starts_with(&format!("| {split} |"))).unwrap_or_else(|| panic!("no {split} row in {report}"));
        let ap: f64 = row.split('|').nth(2).unwrap().trim().parse().unwrap_or_else(|_| panic!("no AP in {row}"));
        assert!((0.0..=1.0).contains(&ap));
        assert!(out.join("line2d").join(split).join("eval/metrics.json").exists());
    }
    let state: Value = serde_json::from_str(&std::fs::read_to_string(out.join("bench_state.json")).unwrap()).unwrap();
    assert!(state["line2d/no-tags"]["seconds"].as_f64().unwrap() > 0.0);
    // A second run resumes: every stage is skipped, the report is rewritten.
    let o = ok(&args);
    assert!(stderr(&o).contains("line2d/with-tags: done in an earlier run, skipped"), "{}", stderr(&o));
}

#[test]
fn calib_groundtruth_adds_tag_pair_poses_close_to_the_exact_ones() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("dataset");
    ok(&["synth", "--preset", "tiny", "--scenes", "2", "--scale", "0.5", "--resolution", "768", "--seed", "3", "--out", p(&ds)]);
    let before = std::fs::read(ds.join("annotations.json")).unwrap();
    // Images detected one at a time or several at once (one single-threaded detector each,
    // record 0079) give the same file.
    ok(&["calib", "groundtruth", "--dataset", p(&ds), "--encoding", "srgb", "--refine-edges", "--threads", "1"]);
    let one_at_a_time = std::fs::read(ds.join("annotations.json")).unwrap();
    std::fs::write(ds.join("annotations.json"), &before).unwrap();
    let o = ok(&["calib", "groundtruth", "--dataset", p(&ds), "--encoding", "srgb", "--refine-edges"]);
    assert!(std::fs::read(ds.join("annotations.json")).unwrap() == one_at_a_time, "--threads 1 and 2 differ");
    let gt: Value = serde_json::from_str(&std::fs::read_to_string(ds.join("annotations.json")).unwrap()).unwrap();
    let mut posed = 0;
    for a in gt["annotations"].as_array().unwrap() {
        let Some(est) = a.get("T_cam_tube_tags") else { continue };
        assert_eq!(a["carries_tags"], true, "tag pose on a tube without tags: {a}");
        let (e, g) = (vec3(&est["translation"]), vec3(&a["T_cam_tube"]["translation"]));
        let d = ((e[0] - g[0]).powi(2) + (e[1] - g[1]).powi(2) + (e[2] - g[2]).powi(2)).sqrt();
        let axis = |r: &Value| [r[0][2].as_f64().unwrap(), r[1][2].as_f64().unwrap(), r[2][2].as_f64().unwrap()];
        let (ae, ag) = (axis(&est["rotation"]), axis(&a["T_cam_tube"]["rotation"]));
        let ang = (ae[0] * ag[0] + ae[1] * ag[1] + ae[2] * ag[2]).abs().min(1.0).acos().to_degrees();
        assert!(d < 0.015 && ang < 1.0, "tag-pair pose {:.1} mm / {ang:.2} deg from the exact pose ({})", d * 1e3, String::from_utf8_lossy(&o.stdout));
        posed += 1;
    }
    assert!(posed >= 1, "no tag pose added: {}", String::from_utf8_lossy(&o.stdout));

    // Refined poses scored against the tag-pair truth (the paper's protocol): only the tagged
    // tubes are truths, and exact seeds refine to within the tag pair's own error.
    let poses = dir.path().join("poses.json");
    ok(&["refine", "--dataset", p(&ds), "--gt-seeds", "0,0", "--out", p(&poses)]);
    let ev = dir.path().join("eval_tags");
    ok(&["eval", "--gt", p(&ds.join("annotations.json")), "--truth-field", "T_cam_tube_tags", "--min-visible", "0", "--poses", &format!("refined={}", p(&poses)), "--out", p(&ev)]);
    let m: Value = serde_json::from_str(&std::fs::read_to_string(ev.join("pose_metrics.json")).unwrap()).unwrap();
    assert_eq!(m["truth_field"], "T_cam_tube_tags");
    let r = &m["poses"][0];
    assert_eq!(r["n_truths"].as_u64().unwrap(), posed as u64, "{r}");
    assert!(r["n_matched"].as_u64().unwrap() >= 1, "{r}");
    let o = tubeloc(&["eval", "--gt", p(&ds.join("annotations.json")), "--truth-field", "T_cam_tube_laser", "--poses", p(&poses)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("no annotation with T_cam_tube_laser"), "{}", stderr(&o));
    let o = tubeloc(&["eval", "--gt", p(&ds.join("annotations.json")), "--in-both-views", "--poses", p(&poses)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("has no right_camera and T_left_right (--in-both-views needs a stereo dataset)"), "{}", stderr(&o));
}

#[test]
fn ground_auto_takes_each_images_nominal_ground_height_and_refuses_a_bad_one() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("dataset");
    ok(&["synth", "--preset", "tiny", "--out", p(&ds)]);
    let ann = ds.join("annotations.json");
    let mut gt: Value = serde_json::from_str(&std::fs::read_to_string(&ann).unwrap()).unwrap();
    for im in gt["images"].as_array().unwrap() {
        let h = im["ground_height_m"].as_f64().unwrap_or(f64::NAN);
        // The tiny preset's no-tags scene is flagstone: its slabs stand 1.2-3.6 cm proud of z = 0.
        let range = if im["terrain"] == "flagstone" { 0.01..0.04 } else { -0.01..0.01 };
        assert!(range.contains(&h), "image {}: {} terrain, ground_height_m {h}", im["id"], im["terrain"]);
    }
    let poses = dir.path().join("poses.json");
    ok(&["refine", "--dataset", p(&ds), "--gt-seeds", "0,0", "--ground", "auto", "--out", p(&poses)]);
    assert!(poses.exists());
    let id = gt["images"][1]["id"].clone();
    gt["images"][1]["ground_height_m"] = Value::from("high");
    std::fs::write(&ann, serde_json::to_string(&gt).unwrap()).unwrap();
    std::fs::remove_file(&poses).unwrap();
    let o = tubeloc(&["refine", "--dataset", p(&ds), "--gt-seeds", "0,0", "--ground", "auto", "--out", p(&poses)]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains(&format!("image {id}: ground_height_m must be a finite number of metres, got \"high\"")), "{}", stderr(&o));
    assert!(!poses.exists(), "nothing is written on bad input");
}

#[test]
fn demo_runs_the_whole_pipeline_and_reports_measured_figures() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    ok(&["demo", "--out", p(&out)]);
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    let row = report.lines().find(|l| l.starts_with("| line2d |")).unwrap_or_else(|| panic!("no line2d row in {report}"));
    let ap: f64 = row.split('|').nth(2).unwrap().trim().parse().unwrap_or_else(|_| panic!("no AP in {row}"));
    assert!((0.0..=1.0).contains(&ap));
    assert!(report.lines().any(|l| l.starts_with("| line2d-refined |")), "{report}");
    for f in ["locate/poses.json", "locate/poses.overlay.png", "eval_poses/pose_metrics.json", "eval_line2d/metrics.json"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    // The tag-pair ground truth of the tagged tube agrees with the exact pose to centimetres.
    let row = report.lines().find(|l| l.contains("two tags |")).unwrap_or_else(|| panic!("no tag-pair row in {report}"));
    let pos: f64 = row.split('|').nth(3).unwrap().trim().parse().unwrap();
    assert!(pos < 10.0, "tag-pair position error {pos} mm");
}

#[test]
fn refine_snaps_coarse_masks_to_the_fitted_silhouettes() {
    use tubeloc_core::{BinaryMask, CocoDataset, Rle, Segmentation};
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("dataset");
    ok(&["synth", "--preset", "tiny", "--scenes", "2", "--scale", "0.5", "--resolution", "512", "--seed", "5", "--out", p(&ds)]);
    let gt = CocoDataset::load(&ds.join("annotations.json")).unwrap();
    let size = |id: u64| gt.images.iter().find(|im| im.id == id).map(|im| (im.height, im.width)).unwrap();
    // A coarse segmenter: each well visible tube's mask moved 3 px down and fattened by 2 px.
    let mut truth = Vec::new();
    let mut coarse = Vec::new();
    for a in &gt.annotations {
        if a.extra.get("visible_fraction").and_then(Value::as_f64).unwrap_or(0.0) < 0.8 {
            continue;
        }
        let (h, w) = size(a.image_id);
        let m = a.segmentation.as_ref().unwrap().to_rle(h, w).unwrap().to_mask().unwrap();
        let shifted = BinaryMask::from_fn(m.width, m.height, |x, y| y >= 3 && m.get(x, y - 3));
        let fat = shifted.dilated(2);
        coarse.push(serde_json::json!({"image_id": a.image_id, "category_id": 1, "score": 0.9, "segmentation": Segmentation::from_rle(&Rle::from_mask(&fat))}));
        truth.push(m);
    }
    assert!(truth.len() >= 2, "tiny scene has {} well visible tubes", truth.len());
    let (results, dets, poses, snapped) = (dir.path().join("coarse.json"), dir.path().join("dets.json"), dir.path().join("poses.json"), dir.path().join("snapped.json"));
    std::fs::write(&results, serde_json::to_string(&coarse).unwrap()).unwrap();
    ok(&["detect", "--method", "external", "--results", p(&results), "--dataset", p(&ds), "--out", p(&dets)]);
    let o = ok(&["refine", "--dataset", p(&ds), "--detections", p(&dets), "--ground", "auto", "--out", p(&poses), "--snapped-out", p(&snapped)]);
    assert!(stderr(&o).contains("masks snapped to their poses"), "{}", stderr(&o));
    let read = |path: &Path| tubeloc_core::detection::read_coco_results(path).unwrap();
    let (before, after) = (read(&dets), read(&snapped));
    assert_eq!(before.len(), after.len());
    // Each output keeps its detection's image and score; masks are compared with the truth
    // they came from (same order within an image).
    let iou = |d: &tubeloc_core::TubeDetection, t: &BinaryMask| {
        let m = d.mask.as_ref().unwrap().to_mask().unwrap();
        tubeloc_refine::silhouette::mask_iou(&m, t)
    };
    let mut k_of_image: std::collections::BTreeMap<u64, Vec<usize>> = Default::default();
    for (k, c) in coarse.iter().enumerate() {
        k_of_image.entry(c["image_id"].as_u64().unwrap()).or_default().push(k);
    }
    let (mut sum_before, mut sum_after, mut n) = (0.0, 0.0, 0);
    let mut seen: std::collections::BTreeMap<u64, usize> = Default::default();
    for (b, a) in before.iter().zip(&after) {
        assert_eq!((b.image_id, b.score), (a.image_id, a.score));
        let j = seen.entry(b.image_id).or_default();
        let t = &truth[k_of_image[&b.image_id][*j]];
        *j += 1;
        sum_before += iou(b, t);
        sum_after += iou(a, t);
        n += 1;
    }
    let (mb, ma) = (sum_before / n as f64, sum_after / n as f64);
    assert!(mb < 0.8, "coarse masks' mean IoU {mb:.3}");
    assert!(ma > 0.9 && ma > mb + 0.1, "snapped masks' mean IoU {ma:.3}, coarse {mb:.3}");

    // Masks that are not snapped (here: none, since no snap reaches agreement 1) are eroded by
    // `stages.snap.kept_erode_px` of the settings file within the image, or kept as they are
    // with 0.
    let mask = |d: &tubeloc_core::TubeDetection| d.mask.as_ref().unwrap().to_mask().unwrap();
    let config = dir.path().join("snap.toml");
    for (erode, expect) in [("1", 1usize), ("0", 0)] {
        std::fs::write(&config, format!("[stages.snap]\nmin_agreement = 1.0\nkept_erode_px = {erode}\n")).unwrap();
        ok(&["refine", "--dataset", p(&ds), "--detections", p(&dets), "--ground", "auto", "--out", p(&poses), "--snapped-out", p(&snapped), "--config", p(&config)]);
        for (b, a) in before.iter().zip(&read(&snapped)) {
            assert_eq!(mask(a), mask(b).eroded_within_image(expect), "kept_erode_px {erode}");
            assert_eq!(a.bbox, mask(a).bbox());
        }
    }

    // Bad settings and a mode without masks are refused before any work.
    std::fs::write(&config, "[stages.snap]\nmin_agreement = 2.0\n").unwrap();
    let o = tubeloc(&["refine", "--dataset", p(&ds), "--detections", p(&dets), "--out", p(&poses), "--snapped-out", p(&snapped), "--config", p(&config)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("snap.toml") && stderr(&o).contains("stages.snap.min_agreement = 2"), "{}", stderr(&o));
    let o = tubeloc(&["refine", "--dataset", p(&ds), "--gt-seeds", "0,0", "--out", p(&poses), "--snapped-out", p(&snapped)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--snapped-out needs --detections"), "{}", stderr(&o));
}

#[test]
fn detect_decoder_config_is_read_and_bad_fields_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("decode.json");
    std::fs::write(&bad, r#"{"mask_logit_rel": 0.4, "mask_threshold_typo": 1}"#).unwrap();
    let o = tubeloc(&["detect", "--method", "learned", "--image", "absent.png", "--decode-config", p(&bad), "--out", p(&dir.path().join("d.json"))]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains("decode.json") && e.contains("unknown field `mask_threshold_typo`"), "{e}");
    assert!(!dir.path().join("d.json").exists(), "no output on error");
    // Values out of range are refused too, naming the file and the field.
    std::fs::write(&bad, r#"{"mask_direction_weight": -1}"#).unwrap();
    let o = tubeloc(&["detect", "--method", "learned", "--image", "absent.png", "--decode-config", p(&bad), "--out", p(&dir.path().join("d.json"))]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains("decode.json") && e.contains("mask_direction_weight = -1"), "{e}");
    assert!(!dir.path().join("d.json").exists(), "no output on error");
}

#[test]
fn refine_stage_settings_bad_fields_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("poses.json");
    for (name, text, expect) in [
        ("two_view.json", r#"{"stages": {"two_view": {"max_iterations_typo": 3}}}"#, "unknown field `max_iterations_typo`"),
        ("stages.toml", "[stages]\nphoto_min_zncc = 3.0\n", "stages.photo_min_zncc = 3"),
        ("stages2.toml", "[stages]\ndisparities = 100\n", "stages.disparities = 100"),
        ("tv.toml", "[stages.two_view]\nnoise_px = -1.0\n", "stages.two_view: noise_px = -1"),
        ("group.toml", "[stagez]\nx = 1\n", "unknown field `stagez`"),
    ] {
        let bad = dir.path().join(name);
        std::fs::write(&bad, text).unwrap();
        let o = tubeloc(&["refine", "--image", "absent.png", "--detections", "absent.json", "--config", p(&bad), "--out", p(&out)]);
        assert_eq!(o.status.code(), Some(1), "{name}");
        let e = stderr(&o);
        assert!(e.contains(name) && e.contains(expect), "{name}: {e}");
        assert!(!out.exists(), "no output on error");
    }
}

#[test]
fn train_average_and_widen_keep_what_the_model_detects_and_refuse_mismatches() {
    let dir = tempfile::tempdir().unwrap();
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/models");
    let (rgb, gray) = (models.join("synthetic_rgb/tubenet.safetensors"), models.join("gray/tubenet.safetensors"));
    // Averaging a model with itself gives the same weights: the soup detects what the model does.
    let soup = dir.path().join("soup.safetensors");
    ok(&["train", "--average", p(&rgb), p(&rgb), "--out", p(&soup)]);
    let ds = dir.path().join("dataset");
    ok(&["synth", "--preset", "tiny", "--scenes", "1", "--scale", "0.25", "--resolution", "256", "--seed", "7", "--out", p(&ds)]);
    let det = |m: &Path, name: &str| -> Vec<Value> {
        let out = dir.path().join(name);
        ok(&["detect", "--method", "learned", "--model", p(m), "--dataset", p(&ds), "--out", p(&out)]);
        serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap()
    };
    let (a, b) = (det(&rgb, "a.json"), det(&soup, "b.json"));
    assert!(!a.is_empty(), "the shipped model finds tubes on the tiny scene");
    assert_eq!(a, b);
    // An RGB and a gray model cannot be averaged: the error names both files; nothing written.
    let bad = dir.path().join("bad.safetensors");
    let o = tubeloc(&["train", "--average", p(&rgb), p(&gray), "--out", p(&bad)]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains("gray/tubenet.safetensors") && e.contains("architecture and preprocessing"), "{e}");
    assert!(!bad.exists(), "no output on error");
    // One model is not an average.
    assert_eq!(tubeloc(&["train", "--average", p(&rgb), "--out", p(&bad)]).status.code(), Some(2));
    // A widened model (one step at a negligible learning rate) detects what the narrow one does.
    let wide = dir.path().join("wide.safetensors");
    let train = ["train", "--train", p(&ds), "--init", p(&rgb), "--steps", "1", "--lr", "1e-12", "--batch", "1", "--crop", "128"];
    ok(&[&train[..], &["--widen", "12", "--out", p(&wide)]].concat());
    let size = |m: &Path| std::fs::metadata(m).unwrap().len() as f64;
    assert!(size(&wide) > 2.0 * size(&rgb), "width 12 holds about (12/8)² the weights of width 8");
    let w = det(&wide, "w.json");
    assert_eq!(a.len(), w.len(), "same detections from the widened model");
    for (x, y) in a.iter().zip(&w) {
        assert!((x["score"].as_f64().unwrap() - y["score"].as_f64().unwrap()).abs() < 1e-3, "{x} vs {y}");
        for k in 0..4 {
            assert!((x["bbox"][k].as_f64().unwrap() - y["bbox"][k].as_f64().unwrap()).abs() <= 1.0, "{x} vs {y}");
        }
    }
    // Narrowing is refused, naming the model; nothing written.
    let o = tubeloc(&[&train[..], &["--widen", "4", "--out", p(&bad)]].concat());
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains("--widen 4") && e.contains("synthetic_rgb/tubenet.safetensors") && e.contains("below the model's 8"), "{e}");
    assert!(!bad.exists(), "no output on error");
}

/// Scores of the false detections on the tube-free frames of the calibration test.
const FALSE_SCORES: [f64; 4] = [0.5, 0.6, 0.7, 0.9];

#[test]
fn eval_gives_intervals_that_resample_an_image_attribute() {
    // Four sols of two images with one tube each: sol 1 found whole, sol 2 half, sols 3 and 4
    // with a false detection above their true one.
    let dir = tempfile::tempdir().unwrap();
    let (mut images, mut anns, mut dets) = (Vec::new(), Vec::new(), Vec::new());
    for id in 1..=8u64 {
        let sol = id.div_ceil(2);
        images.push(serde_json::json!({"id": id, "file_name": format!("{id}.png"), "width": 100, "height": 100, "sol": sol}));
        anns.push(serde_json::json!({"id": id, "image_id": id, "category_id": 1, "bbox": [10, 10, 30, 10], "area": 300, "iscrowd": 0}));
        if sol != 2 || id == 3 {
            dets.push(serde_json::json!({"image_id": id, "category_id": 1, "bbox": [10, 10, 30, 10], "score": 0.5 + 0.05 * id as f64}));
        }
        if sol >= 3 {
            dets.push(serde_json::json!({"image_id": id, "category_id": 1, "bbox": [60, 60, 30, 10], "score": 0.99}));
        }
    }
    let gt = dir.path().join("gt.json");
    std::fs::write(&gt, serde_json::json!({"images": images, "annotations": anns, "categories": [{"id": 1, "name": "tube"}]}).to_string()).unwrap();
    let dt = dir.path().join("dt.json");
    std::fs::write(&dt, serde_json::json!(dets).to_string()).unwrap();
    let out = dir.path().join("ev");
    let o = ok(&["eval", "--gt", p(&gt), "--dt", p(&dt), "--iou-type", "bbox", "--interval-by", "sol", "--out", p(&out)]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("95 % intervals from a bootstrap over the 4 values of sol"), "{}", String::from_utf8_lossy(&o.stdout));
    let read = |f: &str| -> Value { serde_json::from_str(&std::fs::read_to_string(out.join(f)).unwrap()).unwrap() };
    let (iv, metrics) = (read("intervals.json"), read("metrics.json"));
    for (key, stat) in [("ap50", 1), ("ar", 8)] {
        let (x, lo, hi) = (iv[key]["estimate"].as_f64().unwrap(), iv[key]["lo"].as_f64().unwrap(), iv[key]["hi"].as_f64().unwrap());
        assert_eq!(x, metrics["stats"][stat]["value"].as_f64().unwrap(), "{key}: the estimate is the evaluation's");
        assert!(lo < x && x < hi && lo >= 0.0 && hi <= 1.0, "{key}: {x} [{lo}, {hi}]");
        assert_eq!(iv[key]["groups"], 4);
    }
    // An attribute no image carries is named, with the file, and nothing is written.
    let out2 = dir.path().join("ev2");
    let o = tubeloc(&["eval", "--gt", p(&gt), "--dt", p(&dt), "--iou-type", "bbox", "--interval-by", "terrain", "--out", p(&out2)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--interval-by terrain") && stderr(&o).contains("found on no image"), "{}", stderr(&o));
    assert!(!out2.join("metrics.json").exists());
}

#[test]
fn calibrate_bounds_false_detections_on_frames_without_tubes() {
    // Four images with a tube each, four without. Four true detections at 0.95 and four at
    // 0.85, one false one on each tube-free frame (0.5, 0.6, 0.7, 0.9): precision alone (0.3)
    // keeps everything; at most 0.25 false detections per tube-free frame keeps at most one of
    // the four false ones, so the threshold must rise above at least three of them.
    let dir = tempfile::tempdir().unwrap();
    let mut images = Vec::new();
    let mut anns = Vec::new();
    let mut dets = Vec::new();
    for id in 1..=8u64 {
        images.push(serde_json::json!({"id": id, "file_name": format!("{id}.png"), "width": 100, "height": 100}));
        if id <= 4 {
            anns.push(serde_json::json!({"id": id, "image_id": id, "category_id": 1, "bbox": [10, 10, 30, 10], "area": 300, "iscrowd": 0}));
            dets.push(serde_json::json!({"image_id": id, "category_id": 1, "bbox": [10, 10, 30, 10], "score": 0.95}));
            anns.push(serde_json::json!({"id": id + 10, "image_id": id, "category_id": 1, "bbox": [60, 60, 30, 10], "area": 300, "iscrowd": 0}));
            dets.push(serde_json::json!({"image_id": id, "category_id": 1, "bbox": [60, 60, 30, 10], "score": 0.85}));
        } else {
            dets.push(serde_json::json!({"image_id": id, "category_id": 1, "bbox": [50, 50, 30, 10], "score": FALSE_SCORES[id as usize - 5]}));
        }
    }
    let gt = dir.path().join("gt.json");
    std::fs::write(&gt, serde_json::json!({"images": images, "annotations": anns, "categories": [{"id": 1, "name": "tube"}]}).to_string()).unwrap();
    let dt = dir.path().join("dt.json");
    std::fs::write(&dt, serde_json::json!(dets).to_string()).unwrap();
    let cal = dir.path().join("cal.json");
    let run = |extra: &[&str]| {
        let mut a = vec!["eval", "--gt", p(&gt), "--dt", p(&dt), "--iou-type", "bbox", "--calibrate", p(&cal), "--target-precision", "0.3"];
        a.extend_from_slice(extra);
        ok(&a);
        serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(&cal).unwrap()).unwrap()
    };
    let free = run(&[]);
    let bounded = run(&["--max-false-per-negative-image", "0.25"]);
    let (a, b) = (bounded["a"].as_f64().unwrap(), bounded["b"].as_f64().unwrap());
    let prob = |s: f64| {
        let l = (s / (1.0 - s)).ln();
        1.0 / (1.0 + (-(a * l + b)).exp())
    };
    let t = bounded["threshold"].as_f64().unwrap();
    let kept_false = FALSE_SCORES.iter().filter(|&&s| prob(s) >= t).count();
    assert!(kept_false <= 1, "threshold {t} keeps {kept_false} false detections on 4 tube-free frames");
    assert!(t > free["threshold"].as_f64().unwrap(), "bounded {t} vs free {}", free["threshold"]);
    assert_eq!(bounded["max_false_per_negative_image"], 0.25);
    // A ground truth with a tube in every image cannot bound per tube-free image.
    let all = dir.path().join("all.json");
    let mut g: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&gt).unwrap()).unwrap();
    g["images"] = serde_json::json!(g["images"].as_array().unwrap()[..4]);
    std::fs::write(&all, g.to_string()).unwrap();
    let dt4 = dir.path().join("dt4.json");
    std::fs::write(&dt4, serde_json::json!(dets[..8]).to_string()).unwrap();
    let o = tubeloc(&["eval", "--gt", p(&all), "--dt", p(&dt4), "--iou-type", "bbox", "--calibrate", p(&dir.path().join("c2.json")), "--max-false-per-negative-image", "0.25"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("has no image without a tube"), "{}", stderr(&o));
    assert!(!dir.path().join("c2.json").exists());
}

/// `locate --detector fused` seeds the refinement with the detections of `detect --method
/// fused` on the same frame: the learned detections scored by their pose evidence, and
/// Line2D's (at the clutter verifier's cut here: no ground is given).
#[test]
fn fused_locate_refines_the_fused_detections() {
    let s = Scene::new("1", "512");
    let (lib, cam) = (s.path("lib.tlt"), s.path("camera.json"));
    let dets = s.path("fused.json");
    ok(&["detect", "--method", "fused", "--templates", p(&lib), "--camera", p(&cam), "--image", p(&s.image(0)), "--out", p(&dets)]);
    let dets: Value = serde_json::from_str(&std::fs::read_to_string(&dets).unwrap()).unwrap();
    let dets = dets.as_array().unwrap();
    assert!(!dets.is_empty(), "the rendered tubes are found");
    for d in dets {
        let sc = d["score"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&sc), "{d}");
        match d["source"].as_str() {
            Some("line2d") => assert_eq!(d["probability"].as_f64().unwrap(), sc, "without a ground Line2D keeps its clutter probability: {d}"),
            Some("learned") => assert!(d.get("template_id").is_none(), "{d}"),
            other => panic!("source {other:?}: {d}"),
        }
    }
    assert!(dets.iter().any(|d| d["source"] == "learned"), "the learned detector contributes");
    let out = s.path("out/poses.json");
    let o = tubeloc(&["locate", "--rig", p(&s.path("rig.json")), "--image", p(&s.image(0)), "--detector", "fused", "--templates", p(&lib), "--out", p(&out)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(doc["detector"], "fused");
    // Tubes are handed over at the fused calibration's threshold (embedded from its file).
    let cal: Value = serde_json::from_str(&std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/models/fused.calibration.json")).unwrap()).unwrap();
    assert_eq!(doc["min_probability"], cal["threshold"]);
    let scores = |list: &[Value]| -> Vec<f64> { list.iter().map(|d| d["score"].as_f64().unwrap()).collect() };
    assert_eq!(scores(doc["detections"].as_array().unwrap()), scores(dets), "locate's detections are detect's");
    assert!(doc["tubes"].as_array().unwrap().iter().any(|t| t["converged"] == true), "a tube is located");
}

/// Without `--templates`, Line2D and the fused detector search with the default library: the
/// same detections as with the library `tubeloc templates build` writes at its defaults.
#[test]
fn without_templates_the_default_library_is_used() {
    let s = Scene::new("1", "512");
    let (lib, cam) = (s.path("default.tlt"), s.path("camera.json"));
    ok(&["templates", "build", "--out", p(&lib)]);
    for method in ["line2d", "fused"] {
        let (with, without) = (s.path(&format!("{method}_with.json")), s.path(&format!("{method}_without.json")));
        ok(&["detect", "--method", method, "--templates", p(&lib), "--camera", p(&cam), "--image", p(&s.image(0)), "--out", p(&with)]);
        ok(&["detect", "--method", method, "--camera", p(&cam), "--image", p(&s.image(0)), "--out", p(&without)]);
        let read = |f: &Path| -> Value { serde_json::from_str(&std::fs::read_to_string(f).unwrap()).unwrap() };
        let with = read(&with);
        assert!(!with.as_array().unwrap().is_empty(), "{method}: the rendered tubes are found");
        assert_eq!(with, read(&without), "{method}");
    }
    let out = s.path("out/poses.json");
    let o = tubeloc(&["locate", "--rig", p(&s.path("rig.json")), "--image", p(&s.image(0)), "--detector", "fused", "--out", p(&out)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert!(doc["tubes"].as_array().unwrap().iter().any(|t| t["converged"] == true), "a tube is located");
}

#[test]
fn detect_notes_dataset_images_that_carry_no_camera() {
    // Images without a `camera` are detected as they are, not at the working scale: said once,
    // with the count; a dataset whose images all carry one, or `--range-m off`, says nothing.
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    ok(&["synth", "--preset", "tiny", "--scenes", "1", "--scale", "0.25", "--resolution", "256", "--seed", "5", "--out", p(&ds)]);
    let detect = |extra: &[&str]| stderr(&ok(&[&["detect", "--method", "learned", "--dataset", p(&ds), "--out", p(&dir.path().join("d.json"))], extra].concat()));
    assert!(!detect(&[]).contains("carry no `camera`"));
    let ann = ds.join("annotations.json");
    let mut gt: Value = serde_json::from_str(&std::fs::read_to_string(&ann).unwrap()).unwrap();
    let n = gt["images"].as_array().unwrap().len();
    gt["images"][0].as_object_mut().unwrap().remove("camera");
    std::fs::write(&ann, gt.to_string()).unwrap();
    let err = detect(&[]);
    assert!(err.contains(&format!("note: 1 of {n} images")) && err.contains("carry no `camera`") && err.contains("annotations.json"), "{err}");
    assert!(!detect(&["--range-m", "off"]).contains("carry no `camera`"));
}
