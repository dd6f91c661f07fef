//! `TubeMesh::parse_obj` on any UTF-8 text.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;
use tubeloc_core::tube::TubeMesh;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(mesh) = TubeMesh::parse_obj(text, Path::new("fuzz.obj")) {
        let _ = mesh.length();
    }
});
