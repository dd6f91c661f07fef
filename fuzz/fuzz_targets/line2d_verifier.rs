//! Line2D clutter verifiers (`--verifier`, `verifier.json`) from any UTF-8 JSON: an accepted
//! file gives a probability in [0, 1] (never NaN) for feature vectors across their ranges, and
//! cuts that are probabilities.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tubeloc_detect::line2d::classify::{Features, Verifier};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(v) = Verifier::from_json(text) else { return };
    // similarity, contrast [-1, 3], side_min, side_diff, inside_cv, ring_cv, inside_grad,
    // edge_grad, visible [0, 1], log_area, brightness [0, 1].
    let low: Features = [0.0, -1.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let high: Features = [1.0, 3.0, 3.0, 4.0, 10.0, 10.0, 20.0, 20.0, 1.0, 15.0, 1.0];
    let mixed: Features = [0.8, 3.0, -1.0, 4.0, 0.0, 10.0, 0.0, 20.0, 1.0, 0.0, 1.0];
    for f in [low, high, mixed] {
        let p = v.probability(&f);
        assert!((0.0..=1.0).contains(&p), "P = {p}");
    }
    for grey in [false, true] {
        for two in [false, true] {
            assert!((0.0..=1.0).contains(&v.threshold_for_search(grey, two)));
        }
    }
});
