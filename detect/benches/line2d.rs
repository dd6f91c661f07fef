//! Line2D speed on a 1024x1024 image with the default template library (~7000 templates):
//! response-map time (gradients, spreading, response maps, linearization) and matching time
//! (coarse + fine over all templates, NMS) separately, then the same image and silhouettes
//! through OpenCV contrib's `cv2.linemod` LINE-2D (T = {4, 8}) via scripts/linemod_peer.py.
//!
//! Also prints CPU time per image (all threads, from /proc/self/stat), which the load of other
//! processes on a shared machine does not inflate, and the peer's CPU time.
//!
//! Run: `cargo bench -p tubeloc-detect --bench line2d` (set `LINE2D_BENCH_QUICK=1` for a
//! ~700-template library). The peer part needs `pip install opencv-contrib-python-headless`.

use criterion::Criterion;
use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::time::Instant;
use tubeloc_core::{Pose, TubeModel};
use tubeloc_detect::line2d::matching::{match_all, nms, prepare_image};
use tubeloc_detect::line2d::render::{draw_tube_rgb, Pinhole};
use tubeloc_detect::line2d::{LibraryParams, MatchParams, TemplateLibrary};

const W: usize = 1024;
const H: usize = 1024;

fn scene(k: &Pinhole) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let blobs: Vec<(f64, f64, f64, f64)> = (0..400).map(|_| (rng.random_range(0.0..W as f64), rng.random_range(0.0..H as f64), rng.random_range(5.0..60.0), rng.random_range(-40.0..40.0))).collect();
    let mut img = vec![0u8; W * H * 3];
    let mut base = vec![120.0f64; W * H];
    for &(bx, by, r, a) in &blobs {
        let (x0, x1) = ((bx - 2.0 * r).max(0.0) as usize, ((bx + 2.0 * r) as usize).min(W));
        let (y0, y1) = ((by - 2.0 * r).max(0.0) as usize, ((by + 2.0 * r) as usize).min(H));
        for y in y0..y1 {
            for x in x0..x1 {
                base[y * W + x] += a * (-((x as f64 - bx).powi(2) + (y as f64 - by).powi(2)) / (r * r)).exp();
            }
        }
    }
    for i in 0..W * H {
        for (c, f) in [1.15, 0.85, 0.6].iter().enumerate() {
            img[i * 3 + c] = (base[i] * f + rng.random_range(-10.0..10.0)).clamp(0.0, 255.0) as u8;
        }
    }
    let tube = TubeModel::default();
    for (i, (ax, t)) in [((0.7, 0.3, -0.4), (0.1, 0.05, 2.2)), ((-0.2, 0.9, 0.3), (-0.25, -0.2, 1.6)), ((1.0, -0.1, 0.1), (0.3, -0.3, 3.0))].iter().enumerate() {
        let a = Vector3::new(ax.0, ax.1, ax.2).normalize();
        let r = Rotation3::rotation_between(&Vector3::z(), &a).unwrap_or_else(Rotation3::identity);
        let _ = i;
        draw_tube_rgb(&mut img, W, H, &tube, k, &Pose::from_parts(r, Vector3::new(t.0, t.1, t.2)));
    }
    img
}

fn median_ms(mut f: impl FnMut(), n: usize) -> f64 {
    let mut v: Vec<f64> = (0..n)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1000.0
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v[n / 2]
}

/// CPU time (user + system, all threads) of this process so far, ms (Linux `/proc/self/stat`;
/// 0 elsewhere). Under load from other processes wall time inflates but CPU time does not.
fn cpu_ms() -> f64 {
    let Ok(s) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // Fields after the parenthesised command name: state is field 3, utime 14, stime 15.
    let rest = s.rsplit_once(')').map(|x| x.1).unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11).and_then(|v| v.parse().ok()).unwrap_or(0.0) + f.get(12).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    ticks * 10.0 // USER_HZ = 100 on Linux
}

/// Mean CPU time per call over `n` calls, ms.
fn cpu_per_call(mut f: impl FnMut(), n: usize) -> f64 {
    let c0 = cpu_ms();
    for _ in 0..n {
        f();
    }
    (cpu_ms() - c0) / n as f64
}

fn main() {
    let quick = std::env::var("LINE2D_BENCH_QUICK").is_ok();
    let mut params = LibraryParams::default();
    params.camera.cx = (W as f64 - 1.0) / 2.0;
    params.camera.cy = (H as f64 - 1.0) / 2.0;
    if quick {
        params.views.dist_step = 1.0;
    }
    let t = Instant::now();
    let lib = TemplateLibrary::build(&TubeModel::default(), &params, &|_| {}).expect("library");
    eprintln!("library: {} templates built in {:.1} s", lib.len(), t.elapsed().as_secs_f64());
    let img = scene(&params.camera);
    let p = MatchParams::default();

    let mut c = Criterion::default().sample_size(10).configure_from_args();
    c.bench_function("line2d/response_maps_1024", |b| b.iter(|| black_box(prepare_image(&img, W, H, &p).expect("prepare"))));
    let prep = prepare_image(&img, W, H, &p).expect("prepare");
    c.bench_function(&format!("line2d/matching_{}_templates_1024", lib.len()), |b| {
        b.iter(|| {
            let raw = match_all(&prep, &lib, &p);
            black_box(nms(&raw, &lib, p.nms_iou, p.max_detections))
        })
    });
    c.final_summary();

    // Our medians with plain timers (same numbers criterion reports, kept for the ratio).
    let resp_ms = median_ms(|| drop(black_box(prepare_image(&img, W, H, &p))), 9);
    let mut n_det = 0;
    let match_ms = median_ms(
        || {
            let raw = match_all(&prep, &lib, &p);
            n_det = nms(&raw, &lib, p.nms_iou, p.max_detections).len();
        },
        9,
    );
    let ours = resp_ms + match_ms;
    let mut n_raw = 0;
    let raw_ms = median_ms(|| n_raw = match_all(&prep, &lib, &p).len(), 5);
    let raw = match_all(&prep, &lib, &p);
    let nms_ms = median_ms(|| drop(black_box(nms(&raw, &lib, p.nms_iou, p.max_detections))), 5);
    println!("  of which coarse+fine {raw_ms:.1} ms ({n_raw} raw matches), NMS {nms_ms:.1} ms");
    let resp_cpu = cpu_per_call(|| drop(black_box(prepare_image(&img, W, H, &p))), 20);
    let match_cpu = cpu_per_call(|| drop(black_box(nms(&match_all(&prep, &lib, &p), &lib, p.nms_iou, p.max_detections))), 10);
    let det = tubeloc_detect::line2d::Line2dDetector::new(lib.clone(), p.clone()).expect("detector");
    let _ = det.detect(&img, W, H, None).expect("detect"); // fills the verification sample cache
    let detect_ms = median_ms(|| drop(black_box(det.detect(&img, W, H, None))), 5);
    let detect_cpu = cpu_per_call(|| drop(black_box(det.detect(&img, W, H, None))), 5);
    println!("  Line2dDetector::detect end to end (+ verification, re-ranking, masks): {detect_ms:.1} ms wall median, {detect_cpu:.1} ms CPU");
    println!("  CPU time per image (all threads): response maps {resp_cpu:.1} ms, matching {match_cpu:.1} ms, total {:.1} ms = {:.1} ms wall on 2 idle cores if perfectly parallel", resp_cpu + match_cpu, (resp_cpu + match_cpu) / 2.0);
    println!("tubeloc line2d: {} templates, 1024x1024: response maps {resp_ms:.1} ms, matching {match_ms:.1} ms, total {ours:.1} ms median ({n_det} detections, {} threads)", lib.len(), rayon::current_num_threads());

    // Peer: export the image and the silhouettes, run OpenCV's LINE-2D on them.
    let dir = std::env::temp_dir().join("tubeloc_line2d_peer");
    std::fs::create_dir_all(&dir).expect("peer dir");
    let png = image::RgbImage::from_raw(W as u32, H as u32, img.clone()).expect("image");
    png.save(dir.join("image.png")).expect("write image.png");
    let mut masks = (lib.len() as u32).to_le_bytes().to_vec();
    for t in &lib.templates {
        masks.extend_from_slice(&t.levels[0].width.to_le_bytes());
        masks.extend_from_slice(&t.levels[0].height.to_le_bytes());
        masks.extend_from_slice(&t.mask);
    }
    std::fs::write(dir.join("masks.bin"), masks).expect("write masks.bin");
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/linemod_peer.py");
    match std::process::Command::new("python3").arg(&script).arg(&dir).args(["--repeats", "3"]).output() {
        Ok(out) if out.status.success() => {
            let line = String::from_utf8_lossy(&out.stdout);
            println!("peer: {}", line.trim());
            let v = serde_json::from_str::<serde_json::Value>(line.trim()).ok();
            if let Some(ms) = v.as_ref().and_then(|v| v["match_ms_median"].as_f64()) {
                println!("ratio OpenCV / tubeloc (wall, total per image) = {:.2}x", ms / ours);
            }
            if let Some(ms) = v.as_ref().and_then(|v| v["match_cpu_ms_median"].as_f64()) {
                println!("ratio OpenCV / tubeloc (CPU time, total per image) = {:.2}x", ms / (resp_cpu + match_cpu));
            }
        }
        Ok(out) => println!("peer skipped: {}", String::from_utf8_lossy(&out.stdout).trim()),
        Err(e) => println!("peer skipped: python3 not runnable ({e})"),
    }
}
