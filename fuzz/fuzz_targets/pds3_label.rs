//! PDS3 labels (read by `--rig` and `--camera`): any bytes are parsed or refused, never a panic;
//! accepted cameras have a valid model, a rotation and a ground with a unit normal below the
//! camera. A fisheye (CAHVORE) label's model projects and casts rays without a panic, and a
//! pixel's ray, where it has one, images back near that pixel.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;
use tubeloc_calib::interchange::pds_label::{label_camera, resampled_label_camera};

fuzz_target!(|data: &[u8]| {
    let Ok((c, fisheye)) = resampled_label_camera(data, Path::new("x.LBL")) else {
        assert!(label_camera(data, Path::new("x.LBL")).is_err());
        return;
    };
    assert_eq!(label_camera(data, Path::new("x.LBL")).is_ok(), fisheye.is_none());
    assert!(c.camera.model.validate().is_ok());
    assert!((c.camera.t_rig_cam.rotation().determinant() - 1.0).abs() < 1e-9);
    assert!((c.ground.normal.norm() - 1.0).abs() < 1e-9);
    assert!(c.ground.offset < 0.0, "the camera is above its ground");
    if let Some(m) = fisheye {
        let (w, h) = (c.camera.model.width as f64, c.camera.model.height as f64);
        for (x, y) in [(0.0, 0.0), (w / 2.0, h / 2.0), (w - 1.0, h / 3.0)] {
            let Some((origin, dir)) = m.ray(x, y) else { continue };
            assert!(origin.iter().chain(dir.iter()).all(|v| v.is_finite()));
            let _ = m.project(&(origin + 10.0 * dir));
        }
    }
});
