//! Mono refinement time per tube measured as on-CPU time of the calling thread (less sensitive
//! to a loaded machine than wall time): the bench scene of `benches/refine.rs`, refined `N` times
//! (default 200) on the current thread. Linux only (reads `/proc/thread-self/schedstat`).
//!
//! Run: `cargo run --release -p tubeloc-refine --example refine_speed [N]`

#[path = "../tests/common/mod.rs"]
mod common;

use common::*;

/// Nanoseconds this thread has spent on a CPU, if the kernel exposes it.
fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat").ok()?.split_whitespace().next()?.parse().ok()
}

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|v| v.parse().ok()).unwrap_or(200);
    let ss = speed_scene();
    let (refiner, seed, input) = (&ss.refiner, &ss.seed, ss.input());
    let p = refiner.refine_seed(&input, seed, 0, 1.0, None);
    // The kernel's per-thread CPU clock ticks coarsely (a few ms), so the CPU time is taken
    // over the whole loop; the wall-clock median per tube is printed beside it.
    let mut wall = Vec::with_capacity(n);
    let c0 = thread_cpu_ns().unwrap_or(0);
    for _ in 0..n {
        let t0 = std::time::Instant::now();
        let q = refiner.refine_seed(&input, seed, 0, 1.0, None);
        wall.push(t0.elapsed().as_secs_f64() * 1e3);
        assert_eq!(q.centre, p.centre, "refinement is deterministic");
    }
    let cpu = (thread_cpu_ns().unwrap_or(0) - c0) as f64 * 1e-6 / n as f64;
    wall.sort_by(|a, b| a.total_cmp(b));
    println!(
        "converged {} ({} iterations, error {:.2} mm); over {n} runs: mean on-CPU time {cpu:.2} ms per tube, wall median {:.2} ms (p10 {:.2}, p90 {:.2})",
        p.converged,
        p.residuals.iterations,
        (p.centre - ss.scene.truth.centre).norm() * 1e3,
        wall[n / 2],
        wall[n / 10],
        wall[n * 9 / 10]
    );
}
