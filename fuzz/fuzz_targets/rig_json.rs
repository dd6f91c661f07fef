//! Rig JSON (what `Rig::load_json` does: serde + validate) and bare `Pose` JSON; accepted rigs
//! answer relative poses and baselines for every camera pair.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_core::pose::Pose;
use tubeloc_core::rig::Rig;

fuzz_target!(|data: &[u8]| {
    let _ = serde_json::from_slice::<Pose>(data);
    let Ok(rig) = serde_json::from_slice::<Rig>(data) else { return };
    if rig.validate().is_err() {
        return;
    }
    for a in rig.cameras.iter().take(4) {
        for b in rig.cameras.iter().take(4) {
            let _ = rig.relative_pose(&a.name, &b.name);
            let _ = rig.baseline(&a.name, &b.name);
        }
    }
});
