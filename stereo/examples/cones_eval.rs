//! Scores SGM on the Middlebury 2003 "cones" pair and writes the disparity as PFM.
//!
//! `cargo run --release -p tubeloc-stereo --example cones_eval -- [OUT.pfm] ['{"p1":10,...}']`
//! (the optional JSON overrides fields of `SgmParams`; defaults: 64 disparities).

use std::path::Path;
use std::time::Instant;
use tubeloc_core::Plane;
use tubeloc_stereo::metrics::{score, GroundTruth};
use tubeloc_stereo::SgmParams;

fn gray(path: &Path) -> Plane<u8> {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_luma8();
    Plane::from_vec(img.width() as usize, img.height() as usize, img.into_raw())
}

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/stereo/middlebury2003/cones");
    let args: Vec<String> = std::env::args().collect();
    let mut params = serde_json::to_value(SgmParams { num_disparities: 64, ..SgmParams::default() }).unwrap();
    if let Some(j) = args.get(2) {
        let over: serde_json::Value = serde_json::from_str(j).expect("override JSON");
        for (k, v) in over.as_object().expect("object") {
            params[k] = v.clone();
        }
    }
    let params: SgmParams = serde_json::from_value(params).unwrap();
    let (l, r) = (gray(&dir.join("im2.png")), gray(&dir.join("im6.png")));
    let gt = GroundTruth::from_middlebury(&gray(&dir.join("disp2.png")), &gray(&dir.join("disp6.png")), 4.0);
    let repeat: usize = std::env::var("REPEAT").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
    let mut matcher = tubeloc_stereo::SgmMatcher::new(params).unwrap();
    let mut times = Vec::new();
    let mut d = matcher.compute(&l, &r).unwrap();
    for _ in 0..repeat {
        let t = Instant::now();
        d = matcher.compute(&l, &r).unwrap();
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let ms = times[times.len() / 2];
    let s2 = score(&d, &gt, 2.0);
    let s1 = score(&d, &gt, 1.0);
    println!("bad2 {:.4} bad1 {:.4} mae {:.3} density {:.4} evaluated {} median time {ms:.1} ms", s2.bad, s1.bad, s2.mae, s2.density, s2.evaluated);
    if let Some(out) = args.get(1) {
        std::fs::write(out, tubeloc_stereo::io::encode_pfm(&d)).unwrap();
    }
}
