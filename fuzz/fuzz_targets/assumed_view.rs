//! Assumed views (`--assumed-view`, Python `assumed_view`): a spec is a named view or
//! `HFOV_DEG,HEIGHT_M,PITCH_DEG`; an accepted one gives, at any image size, a valid camera and a
//! ground below it with a unit normal.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_core::AssumedView;

fuzz_target!(|data: &[u8]| {
    let Ok(spec) = std::str::from_utf8(data) else { return };
    let Ok(view) = AssumedView::parse(spec) else { return };
    assert!(view.hfov_deg > 1.0 && view.hfov_deg < 170.0 && view.height_m > 0.0 && view.pitch_deg > 0.0 && view.pitch_deg <= 90.0);
    let (rig, ground) = view.rig("f", 640, 480).expect("an accepted view gives a rig");
    assert!(rig.cameras[0].model.validate().is_ok());
    assert!((ground.normal.norm() - 1.0).abs() < 1e-9 && ground.offset < 0.0, "the camera is above its ground");
});
