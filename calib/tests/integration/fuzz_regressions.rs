//! Inputs for the `rig_yaml` fuzz target (fuzz/README.md) kept as regression tests: each must be
//! refused with an error naming the file and field, not a panic.

use std::path::Path;
use tubeloc_calib::yaml::{parse_yaml, rig_from_yaml};

/// `rows * cols` overflowed `usize` (a panic with overflow checks, a wrapped size without):
/// found by reading the code the target drives.
#[test]
fn yaml_matrix_size_overflow_fuzz_regressions() {
    let text = "%YAML:1.0\n---\nm: !!opencv-matrix\n   rows: 4294967296\n   cols: 4294967296\n   dt: d\n   data: [ ]\n";
    let err = parse_yaml(text, Path::new("rig.yaml")).unwrap_err().to_string();
    assert!(err.contains("rig.yaml") && err.contains("line 3") && err.contains("4294967296x4294967296"), "{err}");
    assert!(rig_from_yaml(text, Path::new("rig.yaml")).is_err());
}

/// Lone quote characters and empty flow sequences are refused cleanly.
#[test]
fn yaml_odd_scalars_fuzz_regressions() {
    for text in ["%YAML:1.0\ncamera_count: \"\n", "%YAML:1.0\ncamera_count: 1\nstereo_pairs: [\n", "%YAML:1.0\n:\n", "\u{e9}:#\n"] {
        assert!(rig_from_yaml(text, Path::new("rig.yaml")).is_err(), "{text:?}");
    }
}
