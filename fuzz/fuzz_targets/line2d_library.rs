//! The Line2D template library loader (`TemplateLibrary::from_bytes`, what `load` runs).
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_detect::line2d::TemplateLibrary;

fuzz_target!(|data: &[u8]| {
    let _ = TemplateLibrary::from_bytes(data);
});
