//! COCO results JSON: serde parsing plus `validate_results` against a small fixed ground truth
//! (what `load_results` does).
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;
use tubeloc_core::coco::{validate_results, CocoDataset, CocoResult};

const GT: &str = r#"{"images":[{"id":1,"width":64,"height":48},{"id":2,"width":3,"height":2},
{"id":3,"width":0,"height":0}],"annotations":[],"categories":[{"id":1,"name":"tube"}]}"#;

fuzz_target!(|data: &[u8]| {
    static GT_DS: OnceLock<CocoDataset> = OnceLock::new();
    let gt = GT_DS.get_or_init(|| serde_json::from_str(GT).expect("fixture parses"));
    let Ok(results) = serde_json::from_slice::<Vec<CocoResult>>(data) else { return };
    let _ = validate_results(&results, gt);
});
