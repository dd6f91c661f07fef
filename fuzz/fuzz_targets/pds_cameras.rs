//! PDS camera lists (`cahv_to_pinhole.py`'s JSON, read by `--rig`): accepted cameras have a
//! valid model, a rotation and a ground with a unit normal below the camera.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;
use tubeloc_calib::interchange::pds::pds_cameras;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(cams) = pds_cameras(text, Path::new("cameras.json")) else { return };
    for c in cams {
        assert!(c.camera.model.validate().is_ok());
        assert!((c.ground.normal.norm() - 1.0).abs() < 1e-9);
        assert!(c.ground.offset < 0.0, "the camera is above its ground");
    }
});
