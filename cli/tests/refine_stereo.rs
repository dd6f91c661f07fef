//! `tubeloc refine --dataset --stereo` on a small rendered stereo set (3 pairs of 384 px crops
//! of the paper preset, 20 cm baseline): seeds = exact poses perturbed by 10 mm / 5 degrees.

use serde_json::Value;
use std::path::Path;
use std::process::Command;

fn ok(args: &[&str]) {
    let o = Command::new(env!("CARGO_BIN_EXE_tubeloc")).args(args).output().expect("running tubeloc");
    assert!(o.status.success(), "tubeloc {args:?} failed: {}", String::from_utf8_lossy(&o.stderr));
}

fn read(p: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(p).expect("reading JSON")).expect("parsing JSON")
}

fn vec3(v: &Value) -> [f64; 3] {
    let a = v.as_array().expect("array");
    [a[0].as_f64().expect("x"), a[1].as_f64().expect("y"), a[2].as_f64().expect("z")]
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

#[test]
fn stereo_term_fixes_the_depth_that_mono_loses() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let set = tmp.path().join("st");
    ok(&["synth", "stereo", "--out", set.to_str().unwrap(), "--scenes", "1", "--pairs-per-scene", "3", "--resolution", "384", "--seed", "1"]);
    let ann = read(&set.join("annotations.json"));
    let img0 = &ann["images"][0];
    let fb = img0["camera"]["fx"].as_f64().unwrap() * img0["baseline_m"].as_f64().unwrap();
    // Exact centres per image (tubes at least half visible, as --gt-seeds seeds them, same order).
    let mut truth: std::collections::BTreeMap<u64, Vec<[f64; 3]>> = Default::default();
    for a in ann["annotations"].as_array().unwrap() {
        if a["visible_fraction"].as_f64().unwrap() >= 0.5 {
            truth.entry(a["image_id"].as_u64().unwrap()).or_default().push(vec3(&a["T_cam_tube"]["translation"]));
        }
    }
    let (mut depth_st, mut depth_mono, mut centre_st, mut zs) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for seed in ["0", "1", "2"] {
        let (mono, st) = (tmp.path().join(format!("mono{seed}.json")), tmp.path().join(format!("st{seed}.json")));
        let base = ["refine", "--dataset", set.to_str().unwrap(), "--gt-seeds", "10,5", "--seed", seed];
        ok(&[&base[..], &["--out", mono.to_str().unwrap()]].concat());
        ok(&[&base[..], &["--stereo", "--out", st.to_str().unwrap()]].concat());
        let (pm, ps) = (read(&mono), read(&st));
        let (pm, ps) = (pm.as_array().unwrap(), ps.as_array().unwrap());
        assert_eq!(pm.len(), ps.len());
        for (m, s) in pm.iter().zip(ps) {
            // Tubes outside the right crop have no stereo points: nothing to compare.
            if s["residuals"]["stereo_points"].as_u64().unwrap_or(0) < 50 {
                continue;
            }
            let c = vec3(&s["centre"]);
            let g = truth[&s["image_id"].as_u64().unwrap()]
                .iter()
                .copied()
                .min_by(|a, b| dist(a, &c).total_cmp(&dist(b, &c)))
                .expect("a true tube in the image");
            let n = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            let along = |p: &[f64; 3]| ((p[0] - g[0]) * g[0] + (p[1] - g[1]) * g[1] + (p[2] - g[2]) * g[2]).abs() / n;
            depth_st.push(along(&c));
            depth_mono.push(along(&vec3(&m["centre"])));
            centre_st.push(dist(&c, &g));
            zs.push(g[2]);
        }
    }
    assert!(depth_st.len() >= 8, "only {} tubes with stereo points", depth_st.len());
    let (ds, dm, cs, z) = (median(&mut depth_st), median(&mut depth_mono), median(&mut centre_st), median(&mut zs));
    // SGM's disparity on these ~15 px wide tubes is off by about half a pixel (tube pixels of the
    // stereo crate's evaluation): depth error Z² · 0.5 px / (f B); allow 0.75 px.
    let bound = z * z * 0.75 / fb;
    eprintln!("median depth error: stereo {:.1} mm, mono {:.1} mm (bound {:.1} mm); stereo centre {:.1} mm", ds * 1e3, dm * 1e3, bound * 1e3, cs * 1e3);
    assert!(ds < bound, "stereo median depth error {:.1} mm >= {:.1} mm", ds * 1e3, bound * 1e3);
    assert!(ds < dm / 3.0, "stereo {:.1} mm is not clearly better than mono {:.1} mm in depth", ds * 1e3, dm * 1e3);
    // The seeds are within ±10 mm per coordinate: a stereo fit does not drift beyond twice that.
    assert!(cs < 0.02, "stereo median centre error {:.1} mm", cs * 1e3);
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// `refine` does not depend on `stereo`, so its covariance's count of stereo points per
/// independent measurement mirrors the default SGM census window by hand; this keeps the two
/// in step.
#[test]
fn stereo_points_per_measurement_is_the_default_census_window() {
    let sgm = tubeloc_stereo::sgm::SgmParams::default();
    let refine = tubeloc_refine::RefineConfig::default();
    assert_eq!(refine.stereo_points_per_measurement, (sgm.census_width * sgm.census_height) as f64, "census window {}x{}", sgm.census_width, sgm.census_height);
}
