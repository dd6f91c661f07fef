//! PDS3 labels (read by `--rig` and `--camera`): any bytes are parsed or refused, never a panic;
//! accepted cameras have a valid model, a rotation and a ground with a unit normal below the
//! camera.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;
use tubeloc_calib::interchange::pds_label::label_camera;

fuzz_target!(|data: &[u8]| {
    let Ok(c) = label_camera(data, Path::new("x.LBL")) else { return };
    assert!(c.camera.model.validate().is_ok());
    assert!((c.camera.t_rig_cam.rotation().determinant() - 1.0).abs() < 1e-9);
    assert!((c.ground.normal.norm() - 1.0).abs() < 1e-9);
    assert!(c.ground.offset < 0.0, "the camera is above its ground");
});
