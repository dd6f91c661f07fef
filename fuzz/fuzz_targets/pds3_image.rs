//! PDS3 products (`.IMG` with the label at the head, read by every image reader): any bytes
//! decode or are refused, never a panic; a decoded image has the size the label gives.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;
use tubeloc_detect::pds3_image::{decode, size};

fuzz_target!(|data: &[u8]| {
    // A detached label's data file is looked up beside it: a folder that holds none.
    let path = Path::new("/nonexistent-fuzz-dir/x.IMG");
    let Ok(img) = decode(data, path) else { return };
    assert_eq!(size(data, path), Ok((img.width(), img.height())));
});
