//! Mono refinement time per tube measured as on-CPU time of the calling thread (less sensitive
//! to a loaded machine than wall time), on a scene of `benches/refine.rs` refined `N` times
//! (default 200) on the current thread. Linux only (reads `/proc/thread-self/schedstat`).
//!
//! Cases: `explicit` (default; the explicit seed 3 mm / 2 deg off), `mask-1.2m` and
//! `mask-2.5m` (mask detections with the ground plane: 409 px and 190 px long tubes). Under
//! `valgrind --tool=callgrind` a small `N` gives the instructions per tube, which do not
//! depend on the machine's load.
//!
//! Run: `cargo run --release -p tubeloc-refine --example refine_speed [N] [CASE]`

#[path = "../tests/integration/common/mod.rs"]
mod common;

use common::*;

/// Nanoseconds this thread has spent on a CPU, if the kernel exposes it.
fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat").ok()?.split_whitespace().next()?.parse().ok()
}

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().and_then(|v| v.parse().ok()).unwrap_or(200).max(1);
    let case = args.next().unwrap_or_else(|| "explicit".into());
    assert!(tubeloc_core::heap::keep_freed_memory());
    // Leaked: the timed closures borrow the scenes for the rest of the run.
    let ss: &'static SpeedScene = Box::leak(Box::new(speed_scene()));
    let (scene, run): (&Scene, Box<dyn Fn() -> tubeloc_core::TubeAxisPose>) = match case.as_str() {
        "explicit" => {
            let input = ss.input();
            (&ss.scene, Box::new(move || ss.refiner.refine_seed(&input, &ss.seed, 0, 1.0, None)))
        }
        "mask-1.2m" | "mask-2.5m" => {
            let range = if case == "mask-1.2m" { (1.1, 1.3) } else { (2.4, 2.6) };
            let (scene, det) = mask_seed_scene(range);
            let scene: &'static Scene = Box::leak(Box::new(scene));
            let input = scene.ground_input();
            (scene, Box::new(move || ss.refiner.refine(&input, &det, None)))
        }
        other => panic!("unknown case {other:?}: explicit, mask-1.2m or mask-2.5m"),
    };
    let p = run();
    // The kernel's per-thread CPU clock ticks coarsely (a few ms), so the CPU time is taken
    // over the whole loop; the wall-clock median per tube is printed beside it.
    let mut wall = Vec::with_capacity(n);
    let c0 = thread_cpu_ns().unwrap_or(0);
    for _ in 0..n {
        let t0 = std::time::Instant::now();
        let q = run();
        wall.push(t0.elapsed().as_secs_f64() * 1e3);
        assert_eq!(q.centre, p.centre, "refinement is deterministic");
    }
    let cpu = (thread_cpu_ns().unwrap_or(0) - c0) as f64 * 1e-6 / n as f64;
    wall.sort_by(|a, b| a.total_cmp(b));
    println!(
        "{case}: converged {} ({} iterations, error {:.2} mm); over {n} runs: mean on-CPU time {cpu:.2} ms per tube, wall median {:.2} ms (p10 {:.2}, p90 {:.2})",
        p.converged,
        p.residuals.iterations,
        (p.centre - scene.truth.centre).norm() * 1e3,
        wall[n / 2],
        wall[n / 10],
        wall[n * 9 / 10]
    );
    println!("pose: centre {:?} axis {:?}", p.centre.as_slice(), p.end_direction.as_slice());
}
