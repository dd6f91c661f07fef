//! COCO dataset JSON: serde parsing plus `CocoDataset::validate` (what `CocoDataset::load` does).
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_core::coco::CocoDataset;

fuzz_target!(|data: &[u8]| {
    let Ok(ds) = serde_json::from_slice::<CocoDataset>(data) else { return };
    let _ = ds.validate();
});
