//! `TubeModel::from_toml_str` on any UTF-8 text; accepted models are queried along the axis.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;
use tubeloc_core::tube::TubeModel;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(m) = TubeModel::from_toml_str(text, Path::new("fuzz.toml")) {
        let _ = (m.max_radius(), m.body_radius());
        for i in 0..=8 {
            let _ = m.radius_at(m.length * (i as f64 / 8.0 - 0.5));
        }
        for s in &m.sections {
            let _ = m.section_z_in_tube_frame(s);
        }
    }
});
