//! Line2D end-to-end and exactness tests: a rendered tube is found with its coarse pose; the
//! response-map and linearized paths equal a brute-force evaluation of the similarity; library
//! files round-trip and corrupt files are refused.

use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tubeloc_core::{Pose, TubeModel};
use tubeloc_detect::line2d::gradient::{downsample_rgb, quantize_rgb};
use tubeloc_detect::line2d::matching::{coarse_scores, fine_score_at, fine_search, fine_search_at_least, match_template, prepare_image};
use tubeloc_detect::line2d::render::{intersect_tube, Pinhole};
use tubeloc_detect::line2d::response::similarity;
use tubeloc_detect::line2d::template::{LibraryParams, TemplateLibrary};
use tubeloc_detect::line2d::{Line2dDetector, MatchParams, ViewParams};

/// A Mars-like textured background (smooth blobs + pixel noise) with the tube drawn at
/// `t_cam_tube` (white alumina body and foot, gold seal, a little shading and noise).
fn scene(w: usize, h: usize, k: &Pinhole, t_cam_tube: &Pose, seed: u64) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let blobs: Vec<(f64, f64, f64, f64)> = (0..60).map(|_| (rng.random_range(0.0..w as f64), rng.random_range(0.0..h as f64), rng.random_range(5.0..40.0), rng.random_range(-35.0..35.0))).collect();
    let tube = TubeModel::default();
    let sections: Vec<(f64, f64, f64)> = tube
        .sections
        .iter()
        .map(|s| {
            let (a, b) = tube.section_z_in_tube_frame(s);
            (a, b, s.radius)
        })
        .collect();
    let inv = t_cam_tube.inverse();
    let (o, rot) = (inv.translation(), inv.rotation());
    let mut img = vec![0u8; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let mut base = 120.0;
            for &(bx, by, r, a) in &blobs {
                let d2 = ((x as f64 - bx).powi(2) + (y as f64 - by).powi(2)) / (r * r);
                if d2 < 4.0 {
                    base += a * (-d2).exp();
                }
            }
            let mut rgb = [base * 1.15, base * 0.85, base * 0.6];
            let d = rot * Vector3::new((x as f64 - k.cx) / k.fx, (y as f64 - k.cy) / k.fy, 1.0);
            if let Some(t) = intersect_tube(&sections, &o, &d) {
                let p = o + d * t;
                let zf = p.z + tube.length / 2.0;
                let shade = 0.75 + 0.25 * (p.y / 0.0115).clamp(-1.0, 1.0);
                rgb = if zf > 0.090 { [200.0 * shade, 165.0 * shade, 80.0 * shade] } else { [235.0 * shade, 232.0 * shade, 225.0 * shade] };
            }
            for c in 0..3 {
                let n: f64 = rng.random_range(-12.0..12.0);
                img[(y * w + x) * 3 + c] = (rgb[c] + n).clamp(0.0, 255.0) as u8;
            }
        }
    }
    img
}

fn small_params(dmin: f64, dmax: f64, features: u32) -> LibraryParams {
    LibraryParams { views: ViewParams { dist_min: dmin, dist_max: dmax, ..ViewParams::default() }, features, ..LibraryParams::default() }
}

/// A library of 64-feature templates at `dmin..dmax` metres for a `w x h` image whose principal
/// point is its centre, with its parameters.
fn centred_library(w: usize, h: usize, dmin: f64, dmax: f64) -> (LibraryParams, TemplateLibrary) {
    let mut params = small_params(dmin, dmax, 64);
    params.camera = Pinhole { fx: params.camera.fx, fy: params.camera.fy, cx: (w as f64 - 1.0) / 2.0, cy: (h as f64 - 1.0) / 2.0 };
    let lib = TemplateLibrary::build(&TubeModel::default(), &params, &|_| {}).unwrap();
    (params, lib)
}

#[test]
fn rendered_tube_is_found_with_coarse_pose_within_one_step() {
    let (w, h) = (512usize, 384usize);
    let (params, lib) = centred_library(w, h, 1.8, 2.2);
    assert!(lib.len() > 500, "{} templates", lib.len());
    // True pose: axis 60 degrees off the line of sight, between template views, off-centre.
    let axis = Vector3::new(0.62, 0.35, -0.5).normalize();
    let rot = Rotation3::rotation_between(&Vector3::z(), &axis).unwrap();
    let t_true = Pose::from_parts(rot, Vector3::new(0.07, -0.04, 2.04));
    let img = scene(w, h, &params.camera, &t_true, 7);
    let det = Line2dDetector::new(lib, MatchParams::default()).unwrap();
    let dets = det.detect(&img, w, h, None).unwrap();
    assert!(!dets.is_empty(), "no detection");
    let best = &dets[0];
    // The clutter verifier (on by default) keeps the rendered tube above its threshold.
    let thr = MatchParams::default().verifier.unwrap().threshold;
    let p = best.probability.expect("verifier probability");
    assert!(p >= thr && best.score == p, "probability {p} below the threshold {thr}");
    let k = params.camera;
    let c = t_true.translation();
    let (u, v) = (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
    let err_px = ((best.centre_px[0] - u).powi(2) + (best.centre_px[1] - v).powi(2)).sqrt();
    assert!(err_px < 8.0, "centre {:?} vs ({u:.1}, {v:.1}): {err_px:.1} px", best.centre_px);
    // Coarse pose within one template step: undirected axis angle <= 10 deg view step (+ slack for
    // the off-axis shift), distance within one 0.1 m step.
    let a_det = best.t_cam_tube.rotation().column(2).into_owned();
    let undirected = |a: &Vector3<f64>| a.angle(&axis).min((-a).angle(&axis)).to_degrees();
    // The truth as a template would see it: centre moved onto the optical axis.
    let to_centre = Rotation3::rotation_between(&c.normalize(), &Vector3::z()).unwrap();
    let axis_c = to_centre * axis;
    let nearest = det
        .library
        .templates
        .iter()
        .map(|t| {
            let a = t.axis();
            a.angle(&axis_c).min((-a).angle(&axis_c)).to_degrees()
        })
        .fold(f64::INFINITY, f64::min);
    eprintln!("best: template {} similarity {:.1}, centre error {err_px:.1} px; nearest template axis {nearest:.1} deg", best.template_id, best.similarity);
    if std::env::var("L2D_DEBUG").is_ok() {
        for t0 in [4usize, 2] {
            let pp = MatchParams { t0, threshold: 50.0, coarse_threshold: Some(50.0), ..MatchParams::default() };
            let prep = prepare_image(&img, w, h, &pp).unwrap();
            let (mut a16, mut a8) = (Vec::new(), Vec::new());
            let mut rows = vec![];
            for t in &det.library.templates {
                let a = t.axis();
                let e = a.angle(&axis_c).min((-a).angle(&axis_c)).to_degrees();
                let ms = match_template(&prep, t, &pp, &mut a16, &mut a8);
                let best = ms.iter().map(|m| m.score).fold(0.0f32, f32::max);
                rows.push((best, t.id, e, t.distance));
            }
            rows.sort_by(|a, b| b.0.total_cmp(&a.0));
            for r in rows.iter().take(8) {
                eprintln!("t0={t0} score {:.1} id {} axis err {:.1} dist {:.1}", r.0, r.1, r.2, r.3);
            }
            for r in rows.iter().filter(|r| r.2 < 6.0 && (r.3 - 2.0).abs() < 0.06) {
                eprintln!("t0={t0} near-true: score {:.1} id {} axis err {:.1} dist {:.1}", r.0, r.1, r.2, r.3);
            }
        }
    }
    let ang = undirected(&a_det);
    eprintln!("axis error {ang:.1} deg, distance {:.3} m vs {:.3} m", best.t_cam_tube.translation().norm(), c.norm());
    assert!(ang <= 12.0, "axis error {ang:.1} deg");
    let dist_err = (best.t_cam_tube.translation().norm() - c.norm()).abs();
    assert!(dist_err <= 0.11, "distance error {dist_err:.3} m");
    assert!(best.similarity >= 80.0);
    // The silhouette placed at the detection overlaps the true position.
    assert!(best.bbox[0] <= u && u <= best.bbox[0] + best.bbox[2] && best.bbox[1] <= v && v <= best.bbox[1] + best.bbox[3]);
    // COCO output carries the pose, template id and an RLE of the right area.
    let j = best.to_coco_json(3);
    assert_eq!(j["image_id"], 3);
    assert_eq!(j["template_id"], best.template_id as u64);
    assert!(j["T_cam_tube"]["rotation"].is_array() && j["segmentation"]["counts"].is_string());
    // No confident false positive elsewhere on the background.
    for d in &dets[1..] {
        let e = ((d.centre_px[0] - u).powi(2) + (d.centre_px[1] - v).powi(2)).sqrt();
        assert!(d.similarity < best.similarity || e < 40.0, "competing detection {:?} at {e:.0} px", d.similarity);
    }
}

/// Brute force: `Σ_f max_{d ∈ [-T/2, T - T/2)²} s(o_f, Q(p + p_f + d))` on the one-hot plane `q`.
fn brute(q: &tubeloc_core::Plane<u8>, feats: &[tubeloc_detect::line2d::Feature], t: usize, x: usize, y: usize) -> u32 {
    let lo = (t / 2) as i64;
    feats
        .iter()
        .map(|f| {
            let mut best = 0u8;
            for dy in -lo..(t as i64 - lo) {
                for dx in -lo..(t as i64 - lo) {
                    let (xx, yy) = (x as i64 + f.x as i64 + dx, y as i64 + f.y as i64 + dy);
                    if xx < 0 || yy < 0 || xx >= q.width as i64 || yy >= q.height as i64 {
                        continue;
                    }
                    let m = q.get(xx as usize, yy as usize);
                    if m != 0 {
                        best = best.max(similarity(f.ori, m.trailing_zeros() as u8));
                    }
                }
            }
            best as u32
        })
        .sum()
}

/// An image narrower or shorter than two level-1 tiles holds no template: no detection, not an
/// error (a folder of frames is not stopped by one thumbnail); a wrong buffer is still refused.
#[test]
fn an_image_too_small_for_any_template_gives_no_detection() {
    let (_, lib) = centred_library(64, 48, 1.8, 2.2);
    let det = Line2dDetector::new(lib, MatchParams::default()).unwrap();
    let t1 = MatchParams::default().t1;
    for (w, h) in [(1, 1), (40, 2 * t1 - 1), (2 * t1 - 1, 40)] {
        let img: Vec<u8> = (0..w * h * 3).map(|i| (i * 37 % 251) as u8).collect();
        assert_eq!(det.detect(&img, w, h, None).unwrap().len(), 0, "{w}x{h}");
    }
    assert!(det.detect(&[0u8; 5], 40, 7, None).is_err());
}

#[test]
fn response_maps_and_linear_memories_equal_brute_force() {
    let (w, h) = (160usize, 128usize);
    // 150 features per level: more than 63, so the u8 blocks are widened into u16 totals.
    let mut params = small_params(1.0, 1.0, 150);
    params.views.step_deg = 30.0;
    let lib = TemplateLibrary::build(&TubeModel::default(), &params, &|_| {}).unwrap();
    let t = lib.templates.iter().find(|t| t.levels[0].width < 120 && t.levels[0].height < 100 && t.levels[0].features.len() > 63).expect("a small template").clone();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let img: Vec<u8> = (0..w * h * 3).map(|_| rng.random_range(0..=255u8)).collect();
    let p = MatchParams { threshold: 0.0, coarse_threshold: Some(0.0), ..MatchParams::default() };
    let prep = prepare_image(&img, w, h, &p).unwrap();
    // Level 0: direct response-map sums at every valid position.
    let q0 = quantize_rgb(&img, w, h, &p.gradient);
    let (tw, th) = (t.levels[0].width as usize, t.levels[0].height as usize);
    let mut checked = 0;
    for y in (0..=h - th).step_by(3) {
        for x in (0..=w - tw).step_by(2) {
            assert_eq!(fine_score_at(&prep.resp0, &t, x, y), brute(&q0, &t.levels[0].features, p.t0, x, y), "level 0 at ({x},{y})");
            checked += 1;
        }
    }
    assert!(checked > 100);
    // The 32-lane fine search equals the exhaustive maximum of the direct sums over windows
    // (first position in row-major order on ties), including windows wider than 32 lanes.
    for (x_lo, x_hi, y_lo, y_hi) in [(0, 20, 0, 20), (3, w - tw, 5, 9), (w - tw - 7, w - tw, h - th - 3, h - th)] {
        let mut best = (0u32, x_lo, y_lo);
        for y in y_lo..=y_hi {
            for x in x_lo..=x_hi {
                let e = fine_score_at(&prep.resp0, &t, x, y);
                if e > best.0 {
                    best = (e, x, y);
                }
            }
        }
        assert_eq!(fine_search(&prep.resp0, &t, x_lo, x_hi, y_lo, y_hi, 1), best, "window x {x_lo}..={x_hi}, y {y_lo}..={y_hi}");
        // Every second row, then the rows next to the best: at least the best of the even rows,
        // and its score is the direct sum at its position.
        let even = (y_lo..=y_hi).step_by(2).flat_map(|y| (x_lo..=x_hi).map(move |x| (x, y))).map(|(x, y)| fine_score_at(&prep.resp0, &t, x, y)).max().unwrap();
        let (e2, x2, y2) = fine_search(&prep.resp0, &t, x_lo, x_hi, y_lo, y_hi, 2);
        assert!(e2 >= even && e2 <= best.0);
        assert_eq!(e2, fine_score_at(&prep.resp0, &t, x2, y2));
        // With a required score the search gives the same best when it reaches it, else none
        // (rows are abandoned early only when they cannot reach it); with every second row,
        // the same when an even row reaches it.
        for step in [1, 2] {
            let full = fine_search(&prep.resp0, &t, x_lo, x_hi, y_lo, y_hi, step);
            let best_even = (y_lo..=y_hi).step_by(2).flat_map(|y| (x_lo..=x_hi).map(move |x| (x, y))).map(|(x, y)| fine_score_at(&prep.resp0, &t, x, y)).max().unwrap();
            for need in [0, full.0 / 2, best_even.saturating_sub(3), best_even, best_even + 1, full.0, full.0 + 1, 4 * t.levels[0].features.len() as u32] {
                let got = fine_search_at_least(&prep.resp0, &t, x_lo, x_hi, y_lo, y_hi, step, need);
                if step == 1 || best_even >= need {
                    assert_eq!(got, (full.0 >= need).then_some(full), "need {need}, row step {step}");
                } else {
                    assert_eq!(got, None, "need {need} above every even row, row step {step}");
                }
            }
        }
    }
    // Level 1: linearized memories at every valid grid position.
    let (rgb1, w1, h1) = downsample_rgb(&img, w, h);
    let q1 = quantize_rgb(&rgb1, w1, h1, &p.gradient);
    let (mut a16, mut a8) = (Vec::new(), Vec::new());
    coarse_scores(&prep.lm1, &t, &mut a16, &mut a8);
    let tt = p.t1;
    let (tw1, th1) = (t.levels[1].width as usize, t.levels[1].height as usize);
    let gw = prep.lm1.grid_w;
    for r in 0..=(prep.lm1.grid_h * tt - th1) / tt {
        for c in 0..=(gw * tt - tw1) / tt {
            assert_eq!(a16[r * gw + c] as u32, brute(&q1, &t.levels[1].features, tt, c * tt, r * tt), "level 1 at grid ({c},{r})");
        }
    }
    // The matcher's reported scores are the brute-force scores at the reported positions.
    let (mut a16, mut a8) = (Vec::new(), Vec::new());
    let ms = match_template(&prep, &t, &p, &mut a16, &mut a8);
    assert!(!ms.is_empty());
    for m in ms {
        let e = brute(&q0, &t.levels[0].features, p.t0, m.x as usize, m.y as usize);
        assert_eq!(m.score, 100.0 * e as f32 / (4.0 * t.levels[0].features.len() as f32));
    }
}

#[test]
fn library_round_trip_and_corrupt_files_are_refused() {
    let mut params = small_params(1.5, 1.6, 80);
    params.views.step_deg = 30.0;
    let lib = TemplateLibrary::build(&TubeModel::default(), &params, &|_| {}).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lib.tlt");
    lib.save(&path).unwrap();
    let back = TemplateLibrary::load(&path).unwrap();
    assert_eq!(back.params, lib.params);
    assert_eq!(back.len(), lib.len());
    for (a, b) in back.templates.iter().zip(&lib.templates) {
        let (ang, d) = a.t_cam_tube.distance(&b.t_cam_tube);
        assert!(ang < 1e-9 && d < 1e-12, "pose of template {} changed", a.id);
        let same = a.id == b.id && a.levels == b.levels && a.mask == b.mask && a.centre == b.centre && (a.alpha_deg, a.psi_deg, a.distance) == (b.alpha_deg, b.psi_deg, b.distance);
        assert!(same, "template {} differs after the round trip", a.id);
    }
    assert_eq!(back.templates[0].levels[0].features.len(), 80, "feature count is not capped at 63");
    let bytes = std::fs::read(&path).unwrap();
    let expect_err = |b: &[u8], needle: &str| {
        let p = dir.path().join("bad.tlt");
        std::fs::write(&p, b).unwrap();
        let e = TemplateLibrary::load(&p).unwrap_err().to_string();
        assert!(e.contains("bad.tlt") && e.contains(needle), "{e}");
    };
    expect_err(&bytes[..bytes.len() - 5], "length mismatch");
    expect_err(&bytes[..10], "header");
    let mut flipped = bytes.clone();
    let i = bytes.len() / 2;
    flipped[i] ^= 0x10;
    expect_err(&flipped, "checksum");
    let mut version = bytes.clone();
    version[8] = 9;
    expect_err(&version, "version 9");
    let mut magic = bytes.clone();
    magic[0] = b'X';
    expect_err(&magic, "magic");
    let missing = dir.path().join("missing.tlt");
    assert!(TemplateLibrary::load(&missing).unwrap_err().to_string().contains("missing.tlt"));
}

/// Templates rendered from the CAD mesh (cap excluded) agree with the parametric model's.
#[test]
fn mesh_silhouettes_match_the_parametric_model_and_build_a_library() {
    use tubeloc_core::{TubeMaterial, TubeMesh};
    use tubeloc_detect::line2d::mesh::{render_mesh_silhouette, MeshShape};
    use tubeloc_detect::line2d::render::render_silhouette;
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/sample_tube/sample_tube.obj");
    if !path.exists() {
        if std::env::var_os("CI").is_some() {
            panic!("CI is set but {} is absent (see ../shared/data/README.md)", path.display());
        }
        eprintln!("\n*** SKIPPED mesh_silhouettes_match_the_parametric_model_and_build_a_library: {} is absent ***\n", path.display());
        return;
    }
    let mesh = TubeMesh::load_obj(&path).unwrap();
    let shape = MeshShape::from_mesh(&mesh, &[TubeMaterial::Plastic]).unwrap();
    let tube = TubeModel::default();
    assert!((shape.length() - tube.length).abs() < 0.01, "mesh length {} vs model {}", shape.length(), tube.length);
    let k = Pinhole { fx: 1720.0, fy: 1720.0, cx: 400.0, cy: 300.0 };
    for (axis, t) in [(Vector3::x(), Vector3::new(0.0, 0.0, 1.5)), (Vector3::new(0.6, 0.3, -0.7).normalize(), Vector3::new(0.05, -0.03, 2.2))] {
        let pose = Pose::from_parts(Rotation3::rotation_between(&Vector3::z(), &axis).unwrap(), t);
        let a = render_mesh_silhouette(&shape, &k, &pose, Some((800, 600)));
        let b = render_silhouette(&tube, &k, &pose, Some((800, 600)));
        // IoU of the two silhouettes on the image.
        let at = |s: &tubeloc_detect::line2d::Silhouette, x: i32, y: i32| {
            let (lx, ly) = (x - s.x0, y - s.y0);
            lx >= 0 && ly >= 0 && (lx as usize) < s.width && (ly as usize) < s.height && s.mask[ly as usize * s.width + lx as usize] != 0
        };
        let (mut inter, mut uni) = (0, 0);
        for y in 0..600 {
            for x in 0..800 {
                let (p, q) = (at(&a, x, y), at(&b, x, y));
                inter += (p && q) as usize;
                uni += (p || q) as usize;
            }
        }
        let iou = inter as f64 / uni as f64;
        assert!(iou > 0.8, "mesh vs parametric silhouette IoU {iou:.3} (areas {} / {})", a.area(), b.area());
        // Depth along the line of sight agrees at the centre pixel within 5 mm.
        let (u, v) = ((k.fx * t.x / t.z + k.cx).round() as i32, (k.fy * t.y / t.z + k.cy).round() as i32);
        if at(&a, u, v) && at(&b, u, v) {
            let i = |s: &tubeloc_detect::line2d::Silhouette| ((v - s.y0) as usize) * s.width + (u - s.x0) as usize;
            assert!((a.depth[i(&a)] - b.depth[i(&b)]).abs() < 0.005, "depth {} vs {}", a.depth[i(&a)], b.depth[i(&b)]);
        }
    }
    let mut params = small_params(2.0, 2.0, 48);
    params.views.step_deg = 30.0;
    let lib = TemplateLibrary::build_from_mesh(&shape, &params, &|_| {}).unwrap();
    let reference = TemplateLibrary::build(&tube, &params, &|_| {}).unwrap();
    assert_eq!(lib.len(), reference.len());
    for (m, r) in lib.templates.iter().zip(&reference.templates) {
        assert_eq!(m.levels[0].features.len(), 48);
        let rel = (m.area as f64 - r.area as f64).abs() / r.area as f64;
        assert!(rel < 0.25, "template {}: mesh area {} vs model {}", m.id, m.area, r.area);
    }
}

/// The same scene seen by a camera of another focal length (and image size) is resampled to
/// the library's scale and gives the same detection mapped back: centre within 2 px (of the
/// smaller image), box within 3 px, coarse pose within 0.05 m and 6 degrees of the native one,
/// mask at the smaller image's size.
#[test]
fn a_camera_of_another_focal_length_is_matched_at_the_library_scale() {
    let (w, h) = (512usize, 384usize);
    let (params, lib) = centred_library(w, h, 1.8, 2.2);
    let axis = Vector3::new(0.62, 0.35, -0.5).normalize();
    let t_true = Pose::from_parts(Rotation3::rotation_between(&Vector3::z(), &axis).unwrap(), Vector3::new(0.07, -0.04, 2.04));
    // One search: this test is about the focal-length resampling alone.
    let det = Line2dDetector::new(lib, MatchParams { verifier: None, far_scale: 1.0, ..MatchParams::default() }).unwrap();
    let k = params.camera;
    let native_cam = tubeloc_core::CameraModel { width: w as u32, height: h as u32, fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy, distortion: Default::default() };
    let native = det.detect(&scene(w, h, &k, &t_true, 7), w, h, Some(&native_cam)).unwrap();
    assert!(!native.is_empty());
    assert_eq!(native[0].scale, 1.0);
    // A camera with 0.7 times the focal length, on an image 0.7 times the size.
    let s = 0.7;
    let (w2, h2) = ((w as f64 * s).round() as usize, (h as f64 * s).round() as usize);
    let (sx, sy) = (w2 as f64 / w as f64, h2 as f64 / h as f64);
    let k2 = Pinhole { fx: k.fx * sx, fy: k.fy * sy, cx: (k.cx + 0.5) * sx - 0.5, cy: (k.cy + 0.5) * sy - 0.5 };
    let cam2 = tubeloc_core::CameraModel { width: w2 as u32, height: h2 as u32, fx: k2.fx, fy: k2.fy, cx: k2.cx, cy: k2.cy, distortion: Default::default() };
    let (fsx, fsy) = det.scale_for(Some(&cam2));
    assert!((fsx - 1.0 / sx).abs() < 1e-9 && (fsy - 1.0 / sy).abs() < 1e-9, "{fsx} {fsy}");
    let scaled = det.detect(&scene(w2, h2, &k2, &t_true, 7), w2, h2, Some(&cam2)).unwrap();
    assert!(!scaled.is_empty());
    let (a, b) = (&native[0], &scaled[0]);
    assert!((b.scale - 1.0 / s).abs() < 0.01, "scale {}", b.scale);
    assert_eq!(b.mask.size, [h2 as u32, w2 as u32]);
    let c_native = [(a.centre_px[0] + 0.5) * sx - 0.5, (a.centre_px[1] + 0.5) * sy - 0.5];
    let e = ((b.centre_px[0] - c_native[0]).powi(2) + (b.centre_px[1] - c_native[1]).powi(2)).sqrt();
    assert!(e <= 2.0, "centre {:?} vs native mapped {:?}: {e:.2} px", b.centre_px, c_native);
    let box_native = [a.bbox[0] * sx, a.bbox[1] * sy, a.bbox[2] * sx, a.bbox[3] * sy];
    for i in 0..4 {
        assert!((b.bbox[i] - box_native[i]).abs() <= 3.0, "box {:?} vs native scaled {box_native:?}", b.bbox);
    }
    assert!((b.mask.area() as f64 - a.mask.area() as f64 * sx * sy).abs() <= 0.25 * a.mask.area() as f64 * sx * sy, "mask areas {} vs {}", b.mask.area(), a.mask.area());
    let dt = (b.t_cam_tube.translation() - a.t_cam_tube.translation()).norm();
    let (za, zb) = (a.t_cam_tube.rotation().column(2).into_owned(), b.t_cam_tube.rotation().column(2).into_owned());
    let ang = za.angle(&zb).min((-za).angle(&zb)).to_degrees();
    assert!(dt <= 0.05 && ang <= 6.0, "pose differs by {dt:.3} m, {ang:.1} deg");
    // The coarse pose is consistent with the image's own camera: its centre projects onto the
    // detection's centre pixel.
    let c = b.t_cam_tube.translation();
    let (u, v) = (k2.fx * c.x / c.z + k2.cx, k2.fy * c.y / c.z + k2.cy);
    assert!((u - b.centre_px[0]).abs() < 0.5 && (v - b.centre_px[1]).abs() < 0.5, "pose centre ({u:.1}, {v:.1}) vs {:?}", b.centre_px);
}

/// An RGB8 frame as a grey camera gives it: the luminance in all three channels.
fn grey_of(rgb: &[u8]) -> Vec<u8> {
    tubeloc_detect::line2d::verify::luminance(rgb).into_iter().flat_map(|l| [l, l, l]).collect()
}

/// The verifier's grey cut applies to grey images only: with a grey cut above every
/// probability, the grey version of a scene gives no detection while its colour version keeps
/// the same detections as with the colour cut alone.
#[test]
fn grey_threshold_applies_to_grey_images_only() {
    let (w, h) = (384usize, 320usize);
    let (params, lib) = centred_library(w, h, 1.9, 2.1);
    let rot = Rotation3::rotation_between(&Vector3::z(), &Vector3::new(0.7, 0.2, -0.4).normalize()).unwrap();
    let colour = scene(w, h, &params.camera, &Pose::from_parts(rot, Vector3::new(0.02, 0.01, 2.0)), 3);
    let grey = grey_of(&colour);
    let base = MatchParams::default();
    let plain = Line2dDetector::new(lib.clone(), base.clone()).unwrap();
    let mut v = base.verifier.clone().unwrap();
    v.threshold_grey = Some(1.0);
    let split = Line2dDetector::new(lib, MatchParams { verifier: Some(v.clone()), ..base }).unwrap();
    let c_plain = plain.detect(&colour, w, h, None).unwrap();
    assert!(!c_plain.is_empty(), "no detection in the colour scene");
    assert_eq!(split.detect(&colour, w, h, None).unwrap(), c_plain);
    assert!(!plain.detect(&grey, w, h, None).unwrap().is_empty(), "no detection in the grey scene with one cut");
    assert!(split.detect(&grey, w, h, None).unwrap().is_empty(), "the grey cut of 1 kept a detection");
    // `--min-probability` sets one cut for both kinds.
    v.threshold_far = Some(0.99);
    v.set_threshold(0.0);
    assert_eq!((v.threshold_for(true), v.threshold_for(false), v.threshold_for_search(true, true)), (0.0, 0.0, 0.0));
}

/// A library of templates at 1.8-2.2 m for a `w x h` image ([`centred_library`]), with its
/// Whether detection `d` lies within 6 px of the image of the centre of the tube at `t` under
/// the pinhole `k`.
fn centred_on(d: &tubeloc_detect::line2d::Line2dDetection, k: &Pinhole, t: &Pose) -> bool {
    let c = t.translation();
    let px = [k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy];
    ((d.centre_px[0] - px[0]).powi(2) + (d.centre_px[1] - px[1]).powi(2)).sqrt() <= 6.0
}

/// pinhole and the same camera as a [`tubeloc_core::CameraModel`].
fn library_of_1_8_to_2_2_m(w: usize, h: usize) -> (Pinhole, tubeloc_core::CameraModel, TemplateLibrary) {
    let (params, lib) = centred_library(w, h, 1.8, 2.2);
    let k = params.camera;
    let cam = tubeloc_core::CameraModel { width: w as u32, height: h as u32, fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy, distortion: Default::default() };
    (k, cam, lib)
}

/// A tube `k` times as far as the middle distance (2 m) of [`library_of_1_8_to_2_2_m`], at
/// the same place in the image: beyond its farthest templates for `k` > 1.1.
fn tube_times_1_8_to_2_2_m(k: f64) -> Pose {
    let axis = Vector3::new(0.62, 0.35, -0.5).normalize();
    Pose::from_parts(Rotation3::rotation_between(&Vector3::z(), &axis).unwrap(), Vector3::new(0.05, -0.04 / 1.4, 2.0) * k)
}

/// A tube farther than the library's farthest templates is found by the far search (the image
/// enlarged by `far_scale`), with its coarse pose placed that many times farther along its ray;
/// without the far search it is not found.
#[test]
fn a_tube_beyond_the_library_range_is_found_by_the_far_search() {
    let (w, h) = (512usize, 384usize);
    let (k, cam, lib) = library_of_1_8_to_2_2_m(w, h);
    let t_true = tube_times_1_8_to_2_2_m(1.4);
    let img = scene(w, h, &k, &t_true, 11);
    let c = t_true.translation();
    let near_truth = |d: &tubeloc_detect::line2d::Line2dDetection| centred_on(d, &k, &t_true);
    let one = Line2dDetector::new(lib.clone(), MatchParams { verifier: None, far_scale: 1.0, ..MatchParams::default() }).unwrap();
    assert!(!one.detect(&img, w, h, Some(&cam)).unwrap().iter().any(near_truth), "found without the far search");
    let far = Line2dDetector::new(lib.clone(), MatchParams { verifier: None, far_scale: 1.4, ..MatchParams::default() }).unwrap();
    let dets = far.detect(&img, w, h, Some(&cam)).unwrap();
    let d = dets.iter().find(|d| near_truth(d)).expect("the far tube is found");
    assert!((d.scale - 1.4).abs() < 0.01, "scale {}", d.scale);
    let z = d.t_cam_tube.translation().norm();
    assert!((z - c.norm()).abs() <= 0.15, "coarse distance {z:.2} m vs {:.2} m", c.norm());
    assert_eq!(d.mask.size, [h as u32, w as u32]);
}

/// By default the far search runs on a grey image enlarged to the library's scale (a mono
/// camera with coarser pixels than the library's): its far tube is found there, under the
/// verifier's cut for frames searched twice, while the same frame in colour, or a grey frame
/// at the library's scale, is searched once.
#[test]
fn grey_frames_of_a_coarser_camera_get_the_far_search_by_default() {
    let (w, h) = (512usize, 384usize);
    let (k, _, lib) = library_of_1_8_to_2_2_m(w, h);
    let far = tubeloc_detect::line2d::params::FAR_SCALE_GREY;
    let t_true = tube_times_1_8_to_2_2_m(far);
    // Detections as (resampling factor, whether the centre is within 6 px of the tube's).
    let detect = |det: &Line2dDetector, img: &[u8], kk: &Pinhole| -> Vec<(f64, bool)> {
        let cam = tubeloc_core::CameraModel { width: w as u32, height: h as u32, fx: kk.fx, fy: kk.fy, cx: kk.cx, cy: kk.cy, distortion: Default::default() };
        det.detect(img, w, h, Some(&cam)).unwrap().iter().map(|d| (d.scale, centred_on(d, kk, &t_true))).collect()
    };
    let default = Line2dDetector::new(lib.clone(), MatchParams { verifier: None, ..MatchParams::default() }).unwrap();
    // A camera with 1.2x coarser pixels: its frames are enlarged 1.2x, grey ones then `far` x more.
    let coarse = Pinhole { fx: k.fx / 1.2, fy: k.fy / 1.2, ..k };
    let colour = scene(w, h, &coarse, &t_true, 11);
    let grey = grey_of(&colour);
    let is_far = |s: f64| (s - 1.2 * far).abs() < 0.01;
    let c = detect(&default, &colour, &coarse);
    assert!(c.iter().all(|&(s, _)| (s - 1.2).abs() < 0.01), "a colour frame searched far by default: {c:?}");
    let colour_far = Line2dDetector::new(lib.clone(), MatchParams { verifier: None, far_scale: far, ..MatchParams::default() }).unwrap();
    assert!(detect(&colour_far, &colour, &coarse).iter().any(|&(s, near)| near && is_far(s)), "the far search misses the colour frame's tube");
    let g = detect(&default, &grey, &coarse);
    assert!(g.iter().any(|&(s, near)| near && is_far(s)), "the coarser grey frame's tube is not found by the far search: {g:?}");
    // A grey frame at the library's own scale is searched once by default; with `--far-scale
    // K` for every image its tube is found by the far search.
    let grey1 = grey_of(&scene(w, h, &k, &t_true, 11));
    let g1 = detect(&default, &grey1, &k);
    assert!(!g1.iter().any(|&(s, _)| (s - far).abs() < 0.01), "a grey frame at the library's scale searched far: {g1:?}");
    let both = Line2dDetector::new(lib.clone(), MatchParams { verifier: None, far_scale: far, far_scale_grey: far, ..MatchParams::default() }).unwrap();
    assert!(detect(&both, &grey1, &k).iter().any(|&(s, near)| near && (s - far).abs() < 0.01), "the far search misses the grey frame's tube");
    // Every detection of a frame searched twice takes the verifier's cut for such frames,
    // whatever the kind's cut.
    let mut v = tubeloc_detect::line2d::Verifier::shipped();
    v.threshold_grey = Some(0.0);
    v.threshold_far = Some(1.0);
    let strict = Line2dDetector::new(lib.clone(), MatchParams { verifier: Some(v.clone()), ..MatchParams::default() }).unwrap();
    let gs = detect(&strict, &grey, &coarse);
    assert!(gs.is_empty(), "a detection of a frame searched twice kept under its cut of 1: {gs:?}");
    v.threshold_far = Some(0.0);
    let open = Line2dDetector::new(lib, MatchParams { verifier: Some(v), ..MatchParams::default() }).unwrap();
    assert!(detect(&open, &grey, &coarse).iter().any(|&(s, near)| near && is_far(s)), "the far tube dropped under a far cut of 0");
}

/// The plane on which a tube at `t_cam_tube` lies (its axis in the plane, its centre one body
/// radius above it), facing the camera: upward normal in the camera frame and offset.
fn ground_under(t_cam_tube: &Pose) -> tubeloc_core::GroundPlane {
    let c = t_cam_tube.translation();
    let a = t_cam_tube.rotation() * Vector3::z();
    let u = -c.normalize();
    let n = (u - a * u.dot(&a)).normalize();
    tubeloc_core::GroundPlane::new(n, n.dot(&c) - TubeModel::default().body_radius()).unwrap()
}

/// With its ground known, a tube lying on it is still found (the far search's distances
/// included), while the same tube is dropped under a ground that puts its ray's ground point
/// twice as far or under a ground its ray never reaches; without the check it stays.
#[test]
fn ground_consistency_keeps_a_tube_on_its_ground_and_drops_it_elsewhere() {
    let (w, h) = (512usize, 384usize);
    let (k, cam, lib) = library_of_1_8_to_2_2_m(w, h);
    let axis = Vector3::new(0.62, 0.35, -0.5).normalize();
    let found = |det: &Line2dDetector, t: &Pose, img: &[u8], ground: Option<&tubeloc_core::GroundPlane>| det.detect_on_ground(img, w, h, Some(&cam), ground).unwrap().iter().any(|d| centred_on(d, &k, t));
    let t_true = Pose::from_parts(Rotation3::rotation_between(&Vector3::z(), &axis).unwrap(), Vector3::new(0.07, -0.04, 2.0));
    let img = scene(w, h, &k, &t_true, 11);
    let det = Line2dDetector::new(lib.clone(), MatchParams { verifier: None, ..MatchParams::default() }).unwrap();
    let ground = ground_under(&t_true);
    assert!(found(&det, &t_true, &img, Some(&ground)), "the tube on its own ground is dropped");
    let twice = tubeloc_core::GroundPlane::new(ground.normal, 2.0 * ground.offset).unwrap();
    assert!(!found(&det, &t_true, &img, Some(&twice)), "kept under a ground twice as far");
    // The same plane lifted above the camera: the descending ray never meets it.
    let sky = tubeloc_core::GroundPlane::new(ground.normal, -ground.offset).unwrap();
    assert!(!found(&det, &t_true, &img, Some(&sky)), "kept where its ray never reaches the ground");
    let off = Line2dDetector::new(lib.clone(), MatchParams { verifier: None, ground_range: None, ..MatchParams::default() }).unwrap();
    assert!(found(&off, &t_true, &img, Some(&twice)), "dropped with the check off");
    // A tube 1.4 times farther than the library's middle is found by the far search; its
    // templates' distances count 1.4 times (a tight band that the plain distances miss).
    let t_far = tube_times_1_8_to_2_2_m(1.4);
    let img = scene(w, h, &k, &t_far, 11);
    let tight = Some(tubeloc_detect::line2d::GroundRange::new(0.85, 1.2).unwrap());
    let far = Line2dDetector::new(lib, MatchParams { verifier: None, far_scale: 1.4, ground_range: tight, ..MatchParams::default() }).unwrap();
    assert!(found(&far, &t_far, &img, Some(&ground_under(&t_far))), "the far tube on its ground is dropped");
}
