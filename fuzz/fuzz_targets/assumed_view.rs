//! Assumed views (`--assumed-view`, Python `assumed_view`): a spec is a named view or
//! `HFOV_DEG,HEIGHT_M,PITCH_DEG`; an accepted one gives, at any image size, a valid camera and a
//! ground below it with a unit normal. The same bytes read as a file name
//! (`--assumed-view auto`, `RoverCamera::of_product`): a camera with a view names a view that
//! parses back to it, and the frame's view gives a valid rig.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_core::{AssumedView, RoverCamera};

fn check(view: &AssumedView) {
    assert!(view.hfov_deg > 1.0 && view.hfov_deg < 170.0 && view.height_m > 0.0 && view.pitch_deg > 0.0 && view.pitch_deg <= 90.0);
    let (rig, ground) = view.rig("f", 640, 480).expect("an accepted view gives a rig");
    assert!(rig.cameras[0].model.validate().is_ok());
    assert!((ground.normal.norm() - 1.0).abs() < 1e-9 && ground.offset < 0.0, "the camera is above its ground");
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(view) = AssumedView::parse(text) {
        check(&view);
    }
    if let Some(camera) = RoverCamera::of_product(text) {
        if let Some(view) = camera.view() {
            assert_eq!(AssumedView::parse(&camera.name()).expect("a camera's view is named"), view);
        }
    }
    for grey in [false, true] {
        let frame = AssumedView::of_frame(text, || grey);
        check(&frame.view);
        assert!(!frame.name.is_empty() && frame.unfit.is_none_or(|c| c.view().is_none()));
    }
});
