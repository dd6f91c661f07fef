//! COCO dataset/results loading: round trips with unknown fields, and errors naming the file
//! and the entry.

use std::path::Path;
use tubeloc_core::coco::load_results;
use tubeloc_core::{BinaryMask, CocoDataset, Rle, Segmentation};

const GT: &str = r#"{
 "info": {"description": "t"}, "images": [
  {"id": 1, "width": 6, "height": 4, "file_name": "a.png", "terrain": "sand"},
  {"id": 2, "width": 5, "height": 5, "file_name": "b.png"}],
 "annotations": [
  {"id": 1, "image_id": 1, "category_id": 1, "area": 4, "bbox": [1,1,2,2], "iscrowd": 0,
   "segmentation": [[1,1,3,1,3,3,1,3]], "occlusion": "none"},
  {"id": 2, "image_id": 2, "category_id": 1, "area": 3, "bbox": [0,0,1,3],
   "segmentation": {"size": [5,5], "counts": [0,3,22]}}],
 "categories": [{"id": 1, "name": "tube"}], "tubeloc_version": 3}"#;

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn dataset_round_trip_keeps_unknown_fields() {
    let dir = tempfile::tempdir().unwrap();
    let ds = CocoDataset::load(&write(dir.path(), "gt.json", GT)).unwrap();
    assert_eq!(ds.images[0].extra["terrain"], "sand");
    assert_eq!(ds.annotations[0].extra["occlusion"], "none");
    assert_eq!(ds.extra["tubeloc_version"], 3);
    let out = dir.path().join("out.json");
    ds.save(&out).unwrap();
    assert_eq!(CocoDataset::load(&out).unwrap(), ds);
    let rle = ds.annotations[1].segmentation.as_ref().unwrap().to_rle(5, 5).unwrap();
    assert_eq!(rle.area(), 3);
    assert_eq!(rle.to_bbox(), [0.0, 0.0, 1.0, 3.0]);
}

#[test]
fn results_load_and_validate() {
    let dir = tempfile::tempdir().unwrap();
    let gt = CocoDataset::load(&write(dir.path(), "gt.json", GT)).unwrap();
    let m = BinaryMask::from_fn(6, 4, |x, y| x < 2 && y < 2);
    let seg = serde_json::to_string(&Segmentation::from_rle(&Rle::from_mask(&m))).unwrap();
    let ok = format!(r#"[{{"image_id": 1, "category_id": 1, "score": 0.9, "segmentation": {seg}, "note": 1}}]"#);
    let r = load_results(&write(dir.path(), "dt.json", &ok), &gt).unwrap();
    assert_eq!(r[0].extra["note"], 1);
    assert_eq!(r[0].segmentation.as_ref().unwrap().to_rle(4, 6).unwrap().area(), 4);

    // unknown image id
    let bad = r#"[{"image_id": 1, "category_id": 1, "score": 0.5, "bbox": [0,0,1,1]},
                  {"image_id": 7, "category_id": 1, "score": 0.5, "bbox": [0,0,1,1]}]"#;
    let e = load_results(&write(dir.path(), "unk.json", bad), &gt).unwrap_err().to_string();
    assert!(e.contains("unk.json") && e.contains("results[1]") && e.contains("image_id 7"), "{e}");

    // mask of the wrong size (image 2 is 5x5)
    let wrong = format!(r#"[{{"image_id": 2, "category_id": 1, "score": 0.5, "segmentation": {seg}}}]"#);
    let e = load_results(&write(dir.path(), "size.json", &wrong), &gt).unwrap_err().to_string();
    assert!(e.contains("size.json") && e.contains("results[0]") && e.contains("[4, 6]"), "{e}");

    // malformed JSON
    let e = load_results(&write(dir.path(), "syntax.json", "[{\"image_id\": 1,"), &gt).unwrap_err().to_string();
    assert!(e.contains("syntax.json") && e.contains("line 1"), "{e}");

    // a well-formed file with a bad entry (score missing)
    let e = load_results(
        &write(
            dir.path(),
            "field.json",
            r#"[{"image_id": 1, "category_id": 1, "score": 1},
        {"image_id": 2, "category_id": 1}]"#,
        ),
        &gt,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("field.json") && e.contains("results[1]") && e.contains("score"), "{e}");
}

#[test]
fn dataset_errors_name_the_entry() {
    let dir = tempfile::tempdir().unwrap();
    let unknown = GT.replace(r#""image_id": 2, "category_id": 1, "area": 3"#, r#""image_id": 9, "category_id": 1, "area": 3"#);
    let e = CocoDataset::load(&write(dir.path(), "u.json", &unknown)).unwrap_err().to_string();
    assert!(e.contains("u.json") && e.contains("annotations[1] (id 2)") && e.contains("unknown image_id 9"), "{e}");

    let badmask = GT.replace(r#""size": [5,5], "counts": [0,3,22]"#, r#""size": [5,5], "counts": [0,3,21]"#);
    let e = CocoDataset::load(&write(dir.path(), "m.json", &badmask)).unwrap_err().to_string();
    assert!(e.contains("m.json") && e.contains("annotations[1]") && e.contains("sum to 24"), "{e}");

    let badfield = GT.replace(r#""area": 3,"#, r#""area": "big","#);
    let e = CocoDataset::load(&write(dir.path(), "f.json", &badfield)).unwrap_err().to_string();
    assert!(e.contains("f.json") && e.contains("annotations[1] (id 2)"), "{e}");

    let e = CocoDataset::load(&dir.path().join("missing.json")).unwrap_err().to_string();
    assert!(e.contains("missing.json"), "{e}");
}
