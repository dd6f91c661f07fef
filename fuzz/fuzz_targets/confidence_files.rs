//! Score calibrations (`--calibration`, `tubenet.calibration.json`) and pose-evidence models
//! (`--pose-evidence`, `tubenet.pose_evidence.json`) from any UTF-8 JSON: an accepted file gives
//! a probability in [0, 1] (never NaN) for every score and for every pose's features.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_core::pose_evidence::{PoseEvidence, EVIDENCE_FEATURES};
use tubeloc_core::ScoreCalibration;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(c) = serde_json::from_str::<ScoreCalibration>(text) {
        if c.validate().is_ok() {
            for s in [f64::NEG_INFINITY, -1.0, 0.0, 1e-9, 0.3, 0.5, 0.99, 1.0, 2.0, f64::INFINITY] {
                let p = c.probability(s);
                assert!((0.0..=1.0).contains(&p), "calibration {c:?}: P({s}) = {p}");
            }
        }
    }
    if let Ok(e) = serde_json::from_str::<PoseEvidence>(text) {
        if e.validate().is_ok() {
            // The features' own ranges: logit of a clamped score, a fraction, ln(1 + count),
            // a confidence, ln of an axis sigma of at least 1e-6 rad.
            let corners = [[-13.9, 0.0, 0.0, 0.0, -13.9], [13.9, 1.0, 30.0, 1.0, 5.0], [0.0, 0.5, 4.0, 0.5, -4.0], [13.9, 0.0, 30.0, 0.0, -13.9], [-13.9, 1.0, 0.0, 1.0, 5.0]];
            for f in corners {
                let f: [f64; EVIDENCE_FEATURES] = f;
                let p = e.probability_of(&f);
                assert!((0.0..=1.0).contains(&p), "evidence {e:?}: P({f:?}) = {p}");
            }
        }
    }
});
