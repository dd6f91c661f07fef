//! `LibraryParams::estimate` (what `tubeloc templates build` checks before building) against
//! libraries actually built (hardening issue, item 2).

use tubeloc_core::TubeModel;
use tubeloc_detect::line2d::{LibraryParams, TemplateLibrary, ViewParams};

fn in_memory_bytes(lib: &TemplateLibrary) -> f64 {
    lib.templates.iter().map(|t| std::mem::size_of_val(t) + t.levels.iter().map(|l| std::mem::size_of_val(l) + l.features.len() * std::mem::size_of::<tubeloc_detect::line2d::Feature>()).sum::<usize>() + t.mask.len()).sum::<usize>() as f64
}

#[test]
fn estimate_is_an_upper_bound_of_the_same_order() {
    let tube = TubeModel::default();
    for views in [ViewParams { step_deg: 25.0, dist_min: 1.0, dist_max: 2.0, dist_step: 0.5, ..ViewParams::default() }, ViewParams { step_deg: 30.0, inplane_range_deg: 0.0, dist_min: 0.6, dist_max: 3.0, dist_step: 0.8, ..ViewParams::default() }] {
        let params = LibraryParams { views, ..LibraryParams::default() };
        let e = params.estimate(tube.length, tube.max_radius()).unwrap();
        let lib = TemplateLibrary::build(&tube, &params, &|_| {}).unwrap();
        let actual = in_memory_bytes(&lib);
        let per = actual / lib.len() as f64;
        eprintln!("templates {} (estimate {}), bytes/template {per:.0} (estimate {:.0})", lib.len(), e.templates, e.bytes_per_template);
        assert!(lib.len() as f64 <= e.templates);
        assert!(e.templates <= 5.0 * lib.len() as f64);
        assert!(per <= e.bytes_per_template, "{per} > {}", e.bytes_per_template);
        assert!(e.bytes_per_template <= 20.0 * per);
        assert!(e.peak_bytes >= 2.0 * actual);
    }
}
