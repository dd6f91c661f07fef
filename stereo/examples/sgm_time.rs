//! Median wall time of SGM on the 1024x768, 128-disparity synthetic bench pair, plus its bad-2.0
//! rate on visible pixels (invalid counts as bad). Quick check between criterion runs.
//!
//! `[SIZE=WxH] cargo run --release -p tubeloc-stereo --example sgm_time -- [eight|four] [REPEAT]`

use std::time::Instant;
use tubeloc_stereo::synthetic::bench_scene;
use tubeloc_stereo::{Paths, SgmMatcher, SgmParams};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let paths = if args.get(1).map(|s| s.as_str()) == Some("four") { Paths::Four } else { Paths::Eight };
    let repeat: usize = args.get(2).and_then(|v| v.parse().ok()).unwrap_or(5);
    let size: Vec<usize> = std::env::var("SIZE").unwrap_or_else(|_| "1024x768".into()).split('x').filter_map(|v| v.parse().ok()).collect();
    let (w, h) = (size.first().copied().unwrap_or(1024), size.get(1).copied().unwrap_or(768));
    let pair = bench_scene(w, h, 42);
    let mut m = SgmMatcher::new(SgmParams { num_disparities: 128, paths, ..SgmParams::default() }).expect("params");
    let mut d = m.compute(&pair.left, &pair.right).expect("sgm");
    let mut times = Vec::new();
    for _ in 0..repeat {
        let t = Instant::now();
        d = m.compute(&pair.left, &pair.right).expect("sgm");
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let (mut bad, mut n) = (0usize, 0usize);
    for i in 0..d.data.len() {
        if pair.visible.data[i] == 0 {
            continue;
        }
        n += 1;
        let e = d.data[i];
        if !(e.is_finite() && (e - pair.disparity.data[i]).abs() <= 2.0) {
            bad += 1;
        }
    }
    println!("times_ms {}", times.iter().map(|t| format!("{t:.2}")).collect::<Vec<_>>().join(" "));
    println!("{paths:?}: median {:.1} ms (min {:.1}), bad-2.0 {:.4} on {n} visible px", times[times.len() / 2], times[0], bad as f64 / n as f64);
}
