//! Settings files: a written configuration reads back to the same resolved settings, partial
//! files keep the defaults of what they leave out, and unknown fields or values out of range
//! are refused with the file and the field named.

use tubeloc_refine::{RefineConfig, SeedKind};

/// A configuration away from the defaults in every group.
fn edited() -> RefineConfig {
    let mut c = RefineConfig::default();
    c.edge_search.radius_px = 10;
    c.seed_search.rotation_deg = 5.0;
    c.solver.max_levels = 3;
    c.acceptance.min_inlier_fraction = 0.6;
    c.end_decision.override_confidence = 0.8;
    c.priors.ground_height_known = false;
    c.mono_depth.width_sigma_px = 0.25;
    c.seeds.mask_or_box.ground_tilt_sigma_deg = 2.0;
    c.seeds.template_pose.end_limb_weight = 0.5;
    c.mask.visibility_px = 4;
    c
}

#[test]
fn written_settings_read_back_to_the_same_resolved_values() {
    let dir = tempfile::tempdir().unwrap();
    let c = edited();
    let toml_path = dir.path().join("refine.toml");
    std::fs::write(&toml_path, c.to_toml()).unwrap();
    let json_path = dir.path().join("refine.json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&c).unwrap()).unwrap();
    for path in [&toml_path, &json_path] {
        let back = RefineConfig::load(path).unwrap();
        assert_eq!(back, c, "{}", path.display());
        for kind in SeedKind::ALL {
            assert_eq!(back.resolve(kind), c.resolve(kind), "{} {kind:?}", path.display());
        }
    }
}

#[test]
fn a_partial_file_keeps_the_defaults_of_what_it_leaves_out() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("partial.toml");
    std::fs::write(&path, "[solver]\nmax_levels = 3\n\n[seeds.mask_or_box]\nground_tilt_sigma_deg = 3.0\n").unwrap();
    let got = RefineConfig::load(&path).unwrap();
    let mut want = RefineConfig::default();
    want.solver.max_levels = 3;
    want.seeds.mask_or_box.ground_tilt_sigma_deg = 3.0;
    assert_eq!(got, want);
    // The rest of the mask seeds' profile is theirs, not the explicit seeds'.
    assert!(got.seeds.mask_or_box.keep_depth);
    assert_eq!(got.seeds.mask_or_box.ground_relief_sigma_m, 0.001);
}

#[test]
fn unknown_fields_are_refused_with_the_file_and_field_named() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("top.toml", "mono_length_depth = true\n", "mono_length_depth"),
        ("group.toml", "[solver]\nmax_level = 3\n", "max_level"),
        ("profile.toml", "[seeds.explicit]\nkeep_dept = true\n", "keep_dept"),
        ("flat.json", r#"{"search_radius_px": 8}"#, "search_radius_px"),
        ("group.json", r#"{"edge_search": {"radius": 8}}"#, "radius"),
    ];
    for (name, text, field) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let err = RefineConfig::load(&path).unwrap_err().to_string();
        assert!(err.contains(name) && err.contains(&format!("unknown field `{field}`")), "{name}: {err}");
    }
}

#[test]
fn values_out_of_range_are_refused_with_the_file_and_field_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("levels.toml");
    std::fs::write(&path, "[solver]\nmax_levels = 40\n").unwrap();
    let err = RefineConfig::load(&path).unwrap_err().to_string();
    assert_eq!(err, format!("{}: refine config: solver.max_levels = 40 is out of range 1..=12", path.display()));
}
