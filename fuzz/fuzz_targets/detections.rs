//! `parse_coco_results` (detections with tubeloc's extra fields, axis seeds from masks).
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;
use tubeloc_core::detection::parse_coco_results;

fuzz_target!(|data: &[u8]| {
    if let Ok(dets) = parse_coco_results(data, Path::new("fuzz.json")) {
        for d in &dets {
            let _ = d.axis_seed_from_bbox();
        }
    }
});
