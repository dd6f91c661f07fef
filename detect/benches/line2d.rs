//! Line2D speed on real work: a rendered 1024x1024 paper frame (the synth crate's renderer,
//! paper rig at half resolution, a crop around a tube), the same frame in grey, and real
//! textured 1024x1024 Navcam frames (grey), with the default template library (~8300
//! templates), ours against OpenCV contrib's `cv2.linemod` LINE-2D (T = {4, 8}) on identical
//! templates and frames, in the same run.
//!
//! Per frame: `Line2dDetector::detect` end to end (gradients, response maps, matching,
//! verification, NMS, re-ranking, masks) and the part that OpenCV's `Detector::match` also does
//! (response maps + matching + NMS), at one search scale (as OpenCV searches) and with the far
//! search (the default on grey frames of a camera coarser than the library's), as wall-time
//! medians of repeated in-process runs and CPU time per run (all threads, from /proc/self/stat,
//! which the load of other processes on a shared machine does not inflate). The peer
//! (scripts/linemod_peer.py) times `match` in its own process the same way. Results are
//! printed and written to `<target>/line2d_speed.json`.
//!
//! Run: `cargo bench -p tubeloc-detect --bench line2d`. Env: `LINE2D_BENCH_REAL` (the real
//! frame; default the first frame of `../shared/data/real_mars/backgrounds/msl_navcam_1024`,
//! skipped when absent), `LINE2D_BENCH_REPEATS` (default 5), `LINE2D_BENCH_PYTHON` (the Python
//! with `opencv-contrib-python-headless`, default `python3`), `LINE2D_BENCH_QUICK=1` (a ~700
//! template library), `LINE2D_BENCH_MAX_CANDIDATES` (the candidate cap), `LINE2D_BENCH_CANDIDATES_PER_MPX`
//! (the candidate budget), `LINE2D_BENCH_PEER=0`
//! (ours only). The library is cached in the target folder.

use nalgebra::Point3;
use rand::SeedableRng;
use serde_json::{json, Value};
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;
use tubeloc_core::TubeModel;
use tubeloc_detect::line2d::matching::{match_all, prepare_image};
use tubeloc_detect::line2d::nms::nms;
use tubeloc_detect::line2d::{LibraryParams, Line2dDetector, MatchParams, TemplateLibrary};
use tubeloc_synth::{dataset::crop_around_a_tube, render, rig, RenderOptions, Scene, SceneConfig, TerrainKind, TimeOfDay};

const W: usize = 1024;
const H: usize = 1024;

/// A rendered paper frame: flagstone at noon, the paper rig's camera at half resolution, a
/// 1024x1024 crop that holds a whole tube.
fn paper_frame() -> Vec<u8> {
    let scene = Scene::generate(&SceneConfig::new(TerrainKind::Flagstone, TimeOfDay::Am, false), 7).expect("scene");
    let rig = rig::paper_rig();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    for stop in 0..8 {
        let t_world_rig = rig::stop_pose(&Point3::origin(), rig::STOP_RADIUS_M, rig::HEIGHTS_M[0], stop, 8, scene.stop_offset).expect("stop");
        let cam = &rig.cameras[0];
        let half = cam.model.scaled(0.5);
        let pose = t_world_rig * cam.t_rig_cam;
        if let Some((x0, y0)) = crop_around_a_tube(&scene, &half, &pose, W as i64, &mut rng) {
            let crop = half.cropped(x0 as u32, y0 as u32, W as u32, H as u32);
            return render(&scene, &crop, &pose, &RenderOptions::default()).rgb;
        }
    }
    panic!("no stop shows a whole tube");
}

/// The real frames (RGB): `LINE2D_BENCH_REAL` (paths separated by `:`), else the first and the
/// last 1024x1024 Navcam frame of the shared backgrounds; frames absent or of another size are
/// skipped.
fn real_frames() -> Vec<(PathBuf, Vec<u8>)> {
    let paths: Vec<PathBuf> = match std::env::var("LINE2D_BENCH_REAL") {
        Ok(list) => list.split(':').filter(|p| !p.is_empty()).map(PathBuf::from).collect(),
        Err(_) => {
            let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/real_mars/backgrounds/msl_navcam_1024");
            let mut v: Vec<PathBuf> = std::fs::read_dir(dir).map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect()).unwrap_or_default();
            v.sort();
            match (v.first(), v.last()) {
                (Some(a), Some(b)) if a != b => vec![a.clone(), b.clone()],
                (Some(a), _) => vec![a.clone()],
                _ => vec![],
            }
        }
    };
    paths
        .into_iter()
        .filter_map(|path| {
            let img = image::open(&path).map_err(|e| eprintln!("{}: {e}; skipped", path.display())).ok()?.to_rgb8();
            if (img.width() as usize, img.height() as usize) != (W, H) {
                eprintln!("{}: {}x{}, need {W}x{H}; skipped", path.display(), img.width(), img.height());
                return None;
            }
            Some((path, img.into_raw()))
        })
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// CPU time (user + system, all threads) of this process so far, ms (Linux `/proc/self/stat`;
/// 0 elsewhere).
fn cpu_ms() -> f64 {
    let Ok(s) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // Fields after the parenthesised command name: state is field 3, utime 14, stime 15.
    let rest = s.rsplit_once(')').map(|x| x.1).unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11).and_then(|v| v.parse().ok()).unwrap_or(0.0) + f.get(12).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    ticks * 10.0 // USER_HZ = 100 on Linux
}

/// `(wall median ms, CPU median ms)` of `n` runs of `f`.
fn timed(n: usize, mut f: impl FnMut()) -> (f64, f64) {
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for _ in 0..n {
        let (t, c) = (Instant::now(), cpu_ms());
        f();
        wall.push(t.elapsed().as_secs_f64() * 1e3);
        cpu.push(cpu_ms() - c);
    }
    (median(wall), median(cpu))
}

fn library(quick: bool) -> TemplateLibrary {
    let mut params = LibraryParams::default();
    params.camera.cx = (W as f64 - 1.0) / 2.0;
    params.camera.cy = (H as f64 - 1.0) / 2.0;
    if quick {
        params.views.dist_step = 1.0;
    }
    let cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join(if quick { "line2d_bench_quick.tlt" } else { "line2d_bench.tlt" });
    if let Ok(lib) = TemplateLibrary::load(&cache) {
        if lib.params == params {
            return lib;
        }
    }
    let t = Instant::now();
    let lib = TemplateLibrary::build(&TubeModel::default(), &params, &|_| {}).expect("library");
    eprintln!("library: {} templates built in {:.1} s", lib.len(), t.elapsed().as_secs_f64());
    let _ = lib.save(&cache);
    lib
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return; // `cargo test --benches` lists benchmarks; nothing to list here.
    }
    let quick = std::env::var("LINE2D_BENCH_QUICK").is_ok();
    let repeats: usize = std::env::var("LINE2D_BENCH_REPEATS").ok().and_then(|v| v.parse().ok()).unwrap_or(5).max(1);
    let lib = library(quick);
    let mut p = MatchParams::default();
    if let Some(k) = std::env::var("LINE2D_BENCH_MAX_CANDIDATES").ok().and_then(|v| v.parse().ok()) {
        p.max_candidates = k;
    }
    if let Some(k) = std::env::var("LINE2D_BENCH_CANDIDATES_PER_MPX").ok().and_then(|v| v.parse().ok()) {
        p.max_candidates_per_mpx = k;
    }
    // The peer searches the frame at one scale: so does the detector compared with it. The
    // detector that also searches the frame enlarged by the grey far factor (`--far-scale K`;
    // the default for grey frames of a camera coarser than the library's, such as Navcam) is
    // timed beside.
    let k = tubeloc_detect::line2d::params::FAR_SCALE_GREY;
    let far = Line2dDetector::new(lib.clone(), MatchParams { far_scale: k, far_scale_grey: k, ..p.clone() }).expect("detector");
    p.far_scale = 1.0;
    p.far_scale_grey = 1.0;
    let det = Line2dDetector::new(lib.clone(), p.clone()).expect("detector");
    let paper = paper_frame();
    // The same frame as a mono camera would give it: a real (grey) Navcam frame searched
    // twice is compared with it searched twice.
    let paper_grey: Vec<u8> = tubeloc_detect::line2d::verify::luminance(&paper).into_iter().flat_map(|l| [l, l, l]).collect();
    let mut frames: Vec<(String, String, Vec<u8>)> =
        vec![("paper".into(), "rendered paper frame (flagstone, paper rig at half resolution, 1024x1024 crop)".into(), paper), ("paper_grey".into(), "the rendered paper frame in grey (luminance)".into(), paper_grey)];
    for (k, (path, rgb)) in real_frames().into_iter().enumerate() {
        frames.push((format!("real{}", k + 1), format!("real Navcam frame {}", path.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default()), rgb));
    }
    if frames.len() == 1 {
        eprintln!("no real frame (set LINE2D_BENCH_REAL): rendered frame only");
    }

    // A fresh detector's first image also computes the verification samples of every template
    // that matches (once per process).
    let cold = Line2dDetector::new(lib.clone(), p.clone()).expect("detector");
    let (first_ms, first_cpu) = timed(1, || drop(black_box(cold.detect(&frames[0].2, W, H, None))));
    println!("ours  first image of a fresh detector ({}): {first_ms:.1} ms wall, {first_cpu:.1} ms CPU", frames[0].0);
    // The candidate cap does not bind on the rendered frame: same detections without it.
    let uncapped = Line2dDetector::new(lib.clone(), MatchParams { max_candidates: 0, ..p.clone() }).expect("detector");
    let same = uncapped.detect(&frames[0].2, W, H, None).expect("detect") == det.detect(&frames[0].2, W, H, None).expect("detect");
    println!("ours  {}: detections with max_candidates = {} identical to uncapped: {same}", frames[0].0, p.max_candidates);

    // Ours.
    let mut rows = Vec::new();
    for (name, what, rgb) in &frames {
        let _ = det.detect(rgb, W, H, None).expect("detect"); // fills the verification sample cache
        let mut n_det = 0;
        let (detect_ms, detect_cpu) = timed(repeats, || n_det = black_box(det.detect(rgb, W, H, None).expect("detect")).len());
        let mut n_raw = 0;
        let (core_ms, core_cpu) = timed(repeats, || {
            let prep = prepare_image(rgb, W, H, &p).expect("prepare");
            let raw = match_all(&prep, &lib, &p);
            n_raw = raw.len();
            black_box(nms(&raw, &lib, p.nms_iou, p.max_detections));
        });
        println!("ours  {name:5}: detect {detect_ms:8.1} ms wall, {detect_cpu:8.1} ms CPU ({n_det} detections); response maps + matching + NMS {core_ms:8.1} ms wall, {core_cpu:8.1} ms CPU ({n_raw} raw matches)");
        let (uncapped_ms, uncapped_cpu) = timed(1, || drop(black_box(uncapped.detect(rgb, W, H, None))));
        println!("ours  {name:5}: uncapped (max_candidates = 0) detect {uncapped_ms:8.1} ms wall, {uncapped_cpu:8.1} ms CPU");
        let _ = far.detect(rgb, W, H, None).expect("detect");
        let (far_ms, far_cpu) = timed(repeats, || drop(black_box(far.detect(rgb, W, H, None))));
        println!("ours  {name:5}: detect also at far scale {} {far_ms:8.1} ms wall, {far_cpu:8.1} ms CPU", far.params.far_scale);
        let grey = tubeloc_detect::input::is_grey_rgb8(rgb);
        rows.push(json!({"frame": name, "grey": grey, "far_scale": far.params.far_scale, "far_detect_ms": far_ms, "far_detect_cpu_ms": far_cpu, "uncapped_detect_ms": uncapped_ms, "uncapped_detect_cpu_ms": uncapped_cpu, "what": what, "detect_ms": detect_ms, "detect_cpu_ms": detect_cpu, "detections": n_det, "match_ms": core_ms, "match_cpu_ms": core_cpu, "raw_matches": n_raw}));
    }

    // Peer: the same frames and silhouettes through OpenCV's LINE-2D.
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("line2d_peer");
    std::fs::create_dir_all(&dir).expect("peer dir");
    let mut masks = (lib.len() as u32).to_le_bytes().to_vec();
    for t in &lib.templates {
        masks.extend_from_slice(&t.levels[0].width.to_le_bytes());
        masks.extend_from_slice(&t.levels[0].height.to_le_bytes());
        masks.extend_from_slice(&t.mask);
    }
    std::fs::write(dir.join("masks.bin"), masks).expect("write masks.bin");
    let mut args = vec![dir.to_string_lossy().into_owned(), "--repeats".into(), repeats.to_string()];
    for (name, _, rgb) in &frames {
        let png = dir.join(format!("{name}.png"));
        image::RgbImage::from_raw(W as u32, H as u32, rgb.clone()).expect("image").save(&png).expect("write frame");
        args.extend(["--image".into(), format!("{name}={}", png.display())]);
    }
    if std::env::var("LINE2D_BENCH_PEER").is_ok_and(|v| v == "0") {
        return;
    }
    let python = std::env::var("LINE2D_BENCH_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/linemod_peer.py");
    let peer: Option<Value> = match std::process::Command::new(&python).arg(&script).args(&args).output() {
        Ok(out) if out.status.success() => serde_json::from_slice(&out.stdout).ok(),
        Ok(out) => {
            println!("peer skipped: {}{}", String::from_utf8_lossy(&out.stdout).trim(), String::from_utf8_lossy(&out.stderr).trim());
            None
        }
        Err(e) => {
            println!("peer skipped: {python} not runnable ({e})");
            None
        }
    };
    if let Some(peer) = &peer {
        for row in rows.iter_mut() {
            let name = row["frame"].as_str().unwrap_or_default().to_string();
            let Some(f) = peer["frames"].get(&name) else { continue };
            let (pw, pc) = (f["match_ms_median"].as_f64().unwrap_or(f64::NAN), f["match_cpu_ms_median"].as_f64().unwrap_or(f64::NAN));
            let (ow, oc) = (row["detect_ms"].as_f64().unwrap_or(f64::NAN), row["detect_cpu_ms"].as_f64().unwrap_or(f64::NAN));
            println!("peer  {name:5}: match {pw:8.1} ms wall, {pc:8.1} ms CPU ({} matches); OpenCV / ours (detect end to end): {:.2}x wall, {:.2}x CPU", f["matches"], pw / ow, pc / oc);
            row["opencv_ms"] = json!(pw);
            row["opencv_cpu_ms"] = json!(pc);
            row["opencv_matches"] = f["matches"].clone();
            row["speedup_wall"] = json!(pw / ow);
            row["speedup_cpu"] = json!(pc / oc);
        }
    }
    let (paper, paper_grey) = (rows[0].clone(), rows[1].clone());
    // A real Navcam frame (grey) against the rendered frame: at one scale, and with the far
    // search, which a grey frame of a camera coarser than the library's gets by default,
    // against the rendered frame in grey with the far search.
    for r in rows.iter_mut().skip(2) {
        let over = |k: &str, base: &Value| r[k].as_f64().unwrap_or(f64::NAN) / base[k].as_f64().unwrap_or(f64::NAN);
        let (one_wall, one_cpu, far_cpu) = (over("detect_ms", &paper), over("detect_cpu_ms", &paper), over("far_detect_cpu_ms", &paper_grey));
        println!("{} / paper (detect), one scale: {one_wall:.2}x wall, {one_cpu:.2}x CPU; with the far search / paper_grey with the far search: {far_cpu:.2}x CPU", r["frame"]);
        r["over_paper_cpu"] = json!(one_cpu);
        r["far_over_paper_grey_far_cpu"] = json!(far_cpu);
    }
    let summary = json!({"first_image_ms": first_ms, "first_image_cpu_ms": first_cpu, "capped_equals_uncapped_on_paper": same, "max_candidates": p.max_candidates, "templates": lib.len(), "image": [W, H], "threads": rayon::current_num_threads(), "repeats": repeats, "frames": rows, "peer": peer});
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("line2d_speed.json");
    if std::fs::write(&out, serde_json::to_string_pretty(&summary).unwrap_or_default()).is_ok() {
        println!("-> {}", out.display());
    }
}
