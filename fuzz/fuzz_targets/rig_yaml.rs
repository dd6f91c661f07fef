//! The OpenCV-YAML rig reader of the calib crate (`rig_from_yaml`, which runs `parse_yaml`).
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let _ = tubeloc_calib::yaml::parse_yaml(text, Path::new("fuzz.yaml"));
    let _ = tubeloc_calib::yaml::rig_from_yaml(text, Path::new("fuzz.yaml"));
});
