//! Inputs found by the fuzz targets in `fuzz/` (see fuzz/README.md), kept as regression tests:
//! each must be refused with an error, not a panic, a hang or a huge allocation.

use std::path::Path;
use tubeloc_core::coco::{validate_results, CocoDataset, CocoResult};
use tubeloc_core::detection::parse_coco_results;
use tubeloc_core::mask::{Rle, MAX_MASK_PIXELS, MAX_POLYGON_WALK};

/// `detections` target, out-of-memory: a 65535 x 65535 compressed RLE mask (counts `[0, h*w]`,
/// 8 bytes of text) made `axis_seed_from_mask` allocate a 4 GiB mask.
#[test]
fn detections_huge_mask_fuzz_regressions() {
    let input = br#"[{"image_id":1,"score":0.5,"bbox":[0,0,1,1],"segmentation":{"size":[65535,65535],"counts":"0QPPloo3"}}]"#;
    let err = parse_coco_results(input, Path::new("dets.json")).unwrap_err().to_string();
    assert!(err.contains("dets.json") && err.contains("entry 0"), "{err}");
    assert!(err.contains("65535x65535") && err.contains(&MAX_MASK_PIXELS.to_string()), "{err}");
    // A full mask at the camera's full resolution is still read and seeds the axis.
    let full = Rle { size: [3648, 5472], counts: vec![0, 3648 * 5472] }.to_compressed_string();
    let ok = format!(r#"[{{"image_id":1,"score":0.5,"bbox":[0,0,1,1],"segmentation":{{"size":[3648,5472],"counts":"{full}"}}}}]"#);
    let dets = parse_coco_results(ok.as_bytes(), Path::new("ok.json")).unwrap();
    let seed = dets[0].axis_seed.expect("axis seed from the mask");
    assert!((seed.centre_px[0] - 2735.5).abs() < 1e-6 && (seed.centre_px[1] - 1823.5).abs() < 1e-6, "{seed:?}");
}

/// `coco_results` target, out-of-memory: a polygon vertex at x = 1e8 made the rasterizer walk
/// 5e8 boundary points (2 GiB); 1e300 saturated the integer cast.
#[test]
fn coco_results_far_polygon_fuzz_regressions() {
    let gt: CocoDataset = serde_json::from_str(r#"{"images":[{"id":1,"width":64,"height":48}],"categories":[]}"#).unwrap();
    for x in ["100000000", "1e300", "-1e300"] {
        let text = format!(r#"[{{"image_id":1,"category_id":1,"score":0.5,"segmentation":[[0,0,{x},0,{x},1]]}}]"#);
        let results: Vec<CocoResult> = serde_json::from_str(&text).unwrap();
        let err = validate_results(&results, &gt).unwrap_err();
        assert!(err.contains("results[0]") && err.contains("polygon 0") && err.contains(&MAX_POLYGON_WALK.to_string()), "{err}");
    }
    // Polygons partly outside the image are still rasterized.
    let near: Vec<CocoResult> = serde_json::from_str(r#"[{"image_id":1,"category_id":1,"score":0.5,"segmentation":[[-10,-10,100,0,30,90]]}]"#).unwrap();
    validate_results(&near, &gt).unwrap();
}

/// The same polygon limit through a dataset file (`coco_dataset` target).
#[test]
fn coco_dataset_far_polygon_fuzz_regressions() {
    let text = r#"{"images":[{"id":1,"width":64,"height":48}],"annotations":[{"id":7,"image_id":1,"category_id":1,
        "bbox":[0,0,1,1],"area":1,"iscrowd":0,"segmentation":[[0,0,1,1,2,0],[0,0,0,50000000,1,1]]}],"categories":[]}"#;
    let ds: CocoDataset = serde_json::from_str(text).unwrap();
    let err = ds.validate().unwrap_err();
    assert!(err.contains("annotations[0] (id 7)") && err.contains("polygon 1"), "{err}");
    assert!(Rle::from_polygons(&[vec![0.0, 0.0, f64::MAX, 0.0, 1.0, 1.0]], 4, 4).is_err());
}
