//! The dataset writer: tiny preset contents, determinism, RLE round trips, pycocotools, errors.

use nalgebra::Point3;
use std::path::Path;
use tubeloc_core::{CameraModel, CocoDataset, Pose, Segmentation};
use tubeloc_synth::{write_dataset, DatasetSpec};

fn tiny(dir: &Path, seed: u64) -> tubeloc_synth::DatasetSummary {
    let spec = DatasetSpec::preset("tiny", seed).unwrap();
    write_dataset(&spec, dir, (0, 1), false, &|_, _| {}).unwrap()
}

fn files_under(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for sub in [dir.to_path_buf(), dir.join("images")] {
        let mut names: Vec<_> = std::fs::read_dir(&sub).unwrap().map(|e| e.unwrap().path()).filter(|p| p.is_file()).collect();
        names.sort();
        for p in names {
            out.push((p.strip_prefix(dir).unwrap().display().to_string(), std::fs::read(&p).unwrap()));
        }
    }
    out
}

#[test]
fn tiny_preset_is_complete_exact_and_deterministic() {
    let tmp = tempfile::tempdir().unwrap();
    let a = tmp.path().join("a");
    let summary = tiny(&a, 5);
    assert_eq!(summary.images, 4);
    assert!(summary.annotations >= 4, "{summary:?}");
    let ds = CocoDataset::load(&a.join("annotations.json")).unwrap();
    assert_eq!(ds.categories[0].name, "tube");
    assert!(a.join("rig.json").exists());
    let mut seen_tags = false;
    for img in &ds.images {
        let png = image::open(a.join("images").join(&img.file_name)).unwrap();
        assert_eq!((png.width(), png.height()), (img.width, img.height));
        for key in ["terrain", "time", "height_m", "stop", "camera_name", "split", "scene_seed", "T_world_cam", "camera"] {
            assert!(img.extra.contains_key(key), "image {} lacks {key}", img.id);
        }
        let cam: CameraModel = serde_json::from_value(img.extra["camera"].clone()).unwrap();
        let t_world_cam: Pose = serde_json::from_value(img.extra["T_world_cam"].clone()).unwrap();
        let anns: Vec<_> = ds.annotations.iter().filter(|a| a.image_id == img.id).collect();
        // At least one whole tube per crop (the crop rule of the paper protocol).
        assert!(anns.iter().any(|a| {
            let b = a.extra["amodal_bbox"].as_array().unwrap();
            b[0].as_f64().unwrap() >= 0.0 && b[1].as_f64().unwrap() >= 0.0
        }));
        for ann in anns {
            let Some(Segmentation::CompressedRle { size, counts }) = &ann.segmentation else { panic!("not RLE") };
            let rle = tubeloc_core::Rle::from_compressed_string(counts, *size).unwrap();
            assert_eq!(rle.to_compressed_string(), *counts);
            assert_eq!(rle.area() as f64, ann.area);
            assert_eq!(rle.to_bbox(), ann.bbox);
            let vf = ann.extra["visible_fraction"].as_f64().unwrap();
            assert!(vf > 0.0 && vf <= 1.0);
            // The annotated pose projects into the box when most of the tube is visible.
            let t_cam_tube: Pose = serde_json::from_value(ann.extra["T_cam_tube"].clone()).unwrap();
            if vf > 0.9 {
                let c = cam.project(&Point3::from(t_cam_tube.translation())).unwrap();
                let [x, y, w, h] = ann.bbox;
                assert!(c.x >= x - 1.0 && c.x <= x + w && c.y >= y - 1.0 && c.y <= y + h, "centre {c:?} outside {:?}", ann.bbox);
            }
            let _ = t_world_cam;
        }
        if let Some(tags) = img.extra.get("tags") {
            seen_tags = true;
            for t in tags["tags"].as_array().unwrap() {
                assert_eq!(t["corners_px"].as_array().unwrap().len(), 4);
            }
        }
    }
    assert!(seen_tags, "with-tags images must carry tag corners");
    // Same seed, same bytes; another seed, other images.
    let b = tmp.path().join("b");
    tiny(&b, 5);
    assert_eq!(files_under(&a), files_under(&b));
    let c = tmp.path().join("c");
    tiny(&c, 6);
    assert_ne!(files_under(&a), files_under(&c));
}

#[test]
fn bad_input_is_refused_and_writes_nothing() {
    let err = DatasetSpec::preset("moon", 0).unwrap_err().to_string();
    assert!(err.contains("unknown preset") && err.contains("moon"), "{err}");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("ds");
    let mut spec = DatasetSpec::preset("tiny", 0).unwrap();
    spec.crop = 100_000;
    let err = write_dataset(&spec, &out, (0, 1), false, &|_, _| {}).unwrap_err().to_string();
    assert!(err.contains("crop"), "{err}");
    spec.crop = 64;
    spec.scale = f64::NAN;
    assert!(write_dataset(&spec, &out, (0, 1), false, &|_, _| {}).unwrap_err().to_string().contains("scale"));
    let spec = DatasetSpec::preset("tiny", 0).unwrap();
    assert!(write_dataset(&spec, &out, (2, 2), false, &|_, _| {}).is_err());
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0, "nothing may be left behind");
    // An existing output is not overwritten without `overwrite`.
    std::fs::create_dir(&out).unwrap();
    let err = write_dataset(&spec, &out, (0, 1), false, &|_, _| {}).unwrap_err().to_string();
    assert!(err.contains("already exists"), "{err}");
}

#[test]
fn annotations_load_in_pycocotools() {
    let has = std::process::Command::new("python3").args(["-c", "import pycocotools"]).status().map(|s| s.success()).unwrap_or(false);
    if !has {
        if std::env::var_os("CI").is_some() {
            panic!("CI is set but `python3 -c \"import pycocotools\"` fails: install pycocotools (pip install pycocotools)");
        }
        eprintln!("\n*** SKIPPED annotations_load_in_pycocotools: python3 with pycocotools not found (pip install pycocotools) ***\n");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().join("ds");
    tiny(&d, 9);
    let script = r#"
import sys
from pycocotools.coco import COCO
from pycocotools import mask as M
c = COCO(sys.argv[1])
ids = c.getAnnIds()
assert len(c.getImgIds()) == 4 and len(ids) > 0
for a in c.loadAnns(ids):
    m = c.annToMask(a)
    assert int(m.sum()) == int(a['area']), (m.sum(), a['area'])
    bb = [float(v) for v in M.toBbox(a['segmentation'])]
    assert bb == [float(v) for v in a['bbox']], (bb, a['bbox'])
print('ok', len(ids))
"#;
    let out = std::process::Command::new("python3").args(["-c", script, d.join("annotations.json").to_str().unwrap()]).output().unwrap();
    assert!(out.status.success(), "pycocotools failed: {}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).lines().any(|l| l.starts_with("ok ")), "{}", String::from_utf8_lossy(&out.stdout));
}
