//! End-to-end refinement on rendered scenes with exact ground truth.

use crate::common;

use common::*;
use nalgebra::{Rotation3, Unit, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tubeloc_core::tube_pose::axis_angle;
use tubeloc_refine::{AxisState, RefineConfig, RefineInput, Refiner, Scene as FitScene, Seed};

/// Seed = truth moved by ~`pos_m` in each coordinate and the axis turned by `ang_deg`.
fn perturb(rng: &mut ChaCha8Rng, t: &Truth, pos_m: f64, ang_deg: f64) -> AxisState {
    let dc = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * pos_m;
    let ax = Unit::new_normalize(Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)));
    let r = Rotation3::from_axis_angle(&ax, ang_deg.to_radians());
    AxisState { c: t.centre + dc, a: r * t.axis }
}

struct Errors {
    pos: Vec<f64>,
    ang: Vec<f64>,
    end_ok: usize,
    failed: usize,
    /// Errors of the seeds themselves (position, degrees).
    seed_pos: Vec<f64>,
    seed_ang: Vec<f64>,
}

fn run_batch(n: usize, seed: u64, stereo: bool, distorted: bool, ground: bool, pos_m: f64, ang_deg: f64) -> Errors {
    run_batch_at((0.8, 1.6), n, seed, stereo, distorted, ground, pos_m, ang_deg)
}

/// [`run_batch`] with tubes at distances `dist` (metres).
#[allow(clippy::too_many_arguments)]
fn run_batch_at(dist: (f64, f64), n: usize, seed: u64, stereo: bool, distorted: bool, ground: bool, pos_m: f64, ang_deg: f64) -> Errors {
    let model = default_model();
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let cam = camera(distorted);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut e = Errors { pos: vec![], ang: vec![], end_ok: 0, failed: 0, seed_pos: vec![], seed_ang: vec![] };
    for i in 0..n {
        let (truth, up, gd) = random_truth(&mut rng, &model, &cam, dist);
        let sc = render(&model, &cam, truth, up, gd, None, seed * 1000 + i as u64, 0.01);
        let pts = if stereo { stereo_points(&model, &sc, 4, 0.25, 0.2, i as u64) } else { vec![] };
        let g = ground.then_some(tubeloc_refine::GroundPlane { normal: sc.ground_n, offset: sc.ground_d });
        let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: g, scene: FitScene { depth: None, stereo_points: &pts, ground: None, mask: None, image_axis: None, shown: None } };
        let seed_state = perturb(&mut rng, &truth, pos_m, ang_deg);
        if std::env::var("REFINE_DEBUG").is_ok() {
            eprintln!("scene {i}: truth c {:?} a {:?}; seed c {:?} a {:?}", truth.centre.as_slice(), truth.axis.as_slice(), seed_state.c.as_slice(), seed_state.a.as_slice());
        }
        e.seed_pos.push((seed_state.c - truth.centre).norm());
        e.seed_ang.push(axis_angle(&seed_state.a, &truth.axis).to_degrees());
        let p = refiner.refine_seed(&input, &Seed { state: seed_state, end_known: false }, 0, 1.0, None);
        assert!(p.centre.iter().chain(p.axis.iter()).all(|v| v.is_finite()));
        if !p.converged {
            eprintln!("scene {i}: failed {:?}", p.failure);
            e.failed += 1;
            continue;
        }
        e.pos.push((p.centre - truth.centre).norm());
        e.ang.push(axis_angle(&p.axis, &truth.axis).to_degrees());
        e.end_ok += (p.end_direction.dot(&truth.axis) > 0.0) as usize;
    }
    e
}

fn report(name: &str, e: &mut Errors) -> (f64, f64, f64, f64) {
    let (pm, p9) = med_p90(&mut e.pos);
    let (am, a9) = med_p90(&mut e.ang);
    eprintln!("{name}: position median {:.2} mm p90 {:.2} mm; axis median {:.3} deg p90 {:.3} deg; end ok {}/{}; failed {}", pm * 1e3, p9 * 1e3, am, a9, e.end_ok, e.pos.len(), e.failed);
    (pm, p9, am, a9)
}

/// Seed perturbation (metres, degrees): `PERTURB_MM` (default 3) and `PERTURB_DEG` (default 2).
fn perturbation() -> (f64, f64) {
    let env = |k: &str, default: f64| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok()).unwrap_or(default);
    (env("PERTURB_MM", 3.0) * 1e-3, env("PERTURB_DEG", 2.0))
}

/// Reports batch `name` and asserts at most `max_failed` failures and median position (metres)
/// and axis (degrees) errors below the bounds.
fn check_medians(name: &str, e: &mut Errors, max_failed: usize, pos_m: f64, axis_deg: f64) {
    let (pm, _, am, _) = report(name, e);
    assert!(e.failed <= max_failed, "{name}: {} failed", e.failed);
    assert!(pm < pos_m, "{name}: median position error {pm}");
    assert!(am < axis_deg, "{name}: median axis error {am}");
}

/// The default settings changed by `edit`.
fn config(edit: impl FnOnce(&mut RefineConfig)) -> RefineConfig {
    let mut c = RefineConfig::default();
    edit(&mut c);
    c
}

#[test]
fn mono_perturbed_seeds_converge_back() {
    let (pos, deg) = perturbation();
    let mut e = run_batch(8, 11, false, false, false, pos, deg);
    check_medians("mono", &mut e, 2, 0.010, 2.0);
}

#[test]
fn mono_with_ground_plane_perturbed_seeds_converge_back() {
    let (pos, deg) = perturbation();
    let mut e = run_batch(8, 11, false, false, true, pos, deg);
    check_medians("mono+ground", &mut e, 1, 0.008, 1.0);
}

/// The basin: seeds off by 10 mm in each coordinate and 5 degrees (a Line2D template step),
/// recovered by the coarse seed search (mono target: median position error under 10 mm).
#[test]
fn mono_seeds_off_by_10mm_5deg_converge_back() {
    let mut e = run_batch(8, 13, false, false, false, 0.010, 5.0);
    check_medians("mono 10 mm / 5 deg", &mut e, 1, 0.010, 1.0);
    let mut e = run_batch(8, 14, false, false, true, 0.010, 5.0);
    let (pm, p9, am, a9) = report("mono+ground 10 mm / 5 deg", &mut e);
    assert!(e.failed <= 1, "{} failed", e.failed);
    assert!(pm < 0.008 && p9 < 0.015, "position error median {pm} p90 {p9}");
    assert!(am < 1.0 && a9 < 2.0, "axis error median {am} p90 {a9}");
}

/// Narrow tubes (2-3 m: the body ~20 px wide, the paper preset's regime) where the width fixes
/// the distance worse than the seed: mono refinement keeps the seed's distance and must not
/// degrade 10 mm / 5 degree seeds (it fixes the image-plane quantities).
#[test]
fn mono_narrow_tubes_improve_on_their_seeds() {
    let mut e = run_batch_at((2.0, 3.0), 8, 21, false, false, false, 0.010, 5.0);
    let (pm, p9, am, a9) = report("mono narrow 10 mm / 5 deg", &mut e);
    let (sm, s9) = med_p90(&mut e.seed_pos);
    let (sam, _) = med_p90(&mut e.seed_ang);
    eprintln!("seeds: position median {:.2} mm p90 {:.2} mm; axis median {sam:.2} deg", sm * 1e3, s9 * 1e3);
    assert_eq!(e.failed, 0, "no tube lost");
    assert!(pm < sm && p9 < s9 * 1.1, "position error median {pm} p90 {p9} vs seeds {sm} {s9}");
    assert!(am < sam && a9 < 5.5, "axis error median {am} p90 {a9} vs seeds {sam}");
}

/// Exact seeds on narrow tubes stay put (issue 8: a fit from the truth must not walk away).
#[test]
fn mono_narrow_tubes_exact_seeds_stay_put() {
    let mut e = run_batch_at((2.0, 3.0), 8, 23, false, false, false, 0.0, 0.0);
    let (pm, p9, am, a9) = report("mono narrow exact", &mut e);
    assert_eq!(e.failed, 0, "no tube lost");
    assert!(pm < 0.001 && p9 < 0.002, "position error median {pm} p90 {p9}");
    assert!(am < 0.2 && a9 < 0.5, "axis error median {am} p90 {a9}");
}

#[test]
fn stereo_perturbed_seeds_converge_back() {
    let (pos, _) = perturbation();
    let mut e = run_batch(8, 12, true, true, false, pos, 2.0);
    check_medians("stereo", &mut e, 2, 0.005, 1.0);
}

/// One rendered scene with stereo points, for the flip and rejection tests.
fn one_scene() -> (Scene, Vec<nalgebra::Point3<f64>>) {
    let model = default_model();
    let cam = camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (truth, up, gd) = random_truth(&mut rng, &model, &cam, (0.9, 1.2));
    let sc = render(&model, &cam, truth, up, gd, None, 77, 0.01);
    let pts = stereo_points(&model, &sc, 4, 0.25, 0.2, 5);
    (sc, pts)
}

#[test]
fn flipped_seed_gives_the_same_flip_free_axis_and_end() {
    let (sc, pts) = one_scene();
    let t = sc.truth;
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene { depth: None, stereo_points: &pts, ground: None, mask: None, image_axis: None, shown: None } };
    let a = refiner.refine_seed(&input, &Seed { state: AxisState { c: t.centre, a: t.axis }, end_known: true }, 0, 1.0, None);
    let b = refiner.refine_seed(&input, &Seed { state: AxisState { c: t.centre, a: -t.axis }, end_known: true }, 0, 1.0, None);
    assert!(a.converged && b.converged, "{:?} {:?}", a.failure, b.failure);
    assert!((a.axis - b.axis).norm() < 1e-3, "{:?} vs {:?}", a.axis, b.axis);
    assert!(a.axis.dot(&t.axis).abs() > 0.999);
    // Both hypotheses were compared: the seal end is found whichever way the seed pointed.
    assert!(a.end_direction.dot(&t.axis) > 0.9 && b.end_direction.dot(&t.axis) > 0.9, "{:?} {:?}", a.end_direction, b.end_direction);
    assert!(a.end_confidence > 0.6, "end confidence {}", a.end_confidence);
}

#[test]
fn seed_on_empty_terrain_is_rejected_with_a_reason() {
    let (sc, _) = one_scene();
    let t = sc.truth;
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene::default() };
    // 25 cm beside the tube, still in the image, on textured ground.
    let side = t.axis.cross(&t.centre).normalize() * 0.05;
    let seed = AxisState { c: t.centre + side * 2.0, a: t.axis };
    let p = refiner.refine_seed(&input, &Seed { state: seed, end_known: false }, 0, 1.0, None);
    assert!(p.centre.iter().chain(p.axis.iter()).all(|v| v.is_finite()));
    assert!(!p.converged, "accepted a tube on bare ground: {:?}", p.residuals);
    let f = p.failure.expect("a failure reason");
    eprintln!("empty terrain: {:?}: {}", f.reason, f.message);
    assert!(!f.message.is_empty());
}

#[test]
fn seed_outside_the_image_is_flagged_not_nan() {
    let (sc, _) = one_scene();
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene::default() };
    let seed = AxisState { c: nalgebra::Vector3::new(3.0, 0.0, 1.0), a: nalgebra::Vector3::y() };
    let p = refiner.refine_seed(&input, &Seed { state: seed, end_known: false }, 0, 1.0, None);
    assert!(!p.converged && p.centre.iter().all(|v| v.is_finite()));
    assert_eq!(p.failure.unwrap().reason, tubeloc_core::FailureReason::OutOfImage);
}

/// Refines a perturbed seed on `sc` and checks: finite output; a converged fit is near the
/// truth, a failed one carries a reason.
fn converges_or_is_flagged(name: &str, sc: &Scene, seed_rng: u64) -> tubeloc_core::TubeAxisPose {
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene::default() };
    let mut rng = ChaCha8Rng::seed_from_u64(seed_rng);
    let st = perturb(&mut rng, &sc.truth, 0.003, 2.0);
    let p = refiner.refine_seed(&input, &Seed { state: st, end_known: false }, 0, 1.0, None);
    assert!(p.centre.iter().chain(p.axis.iter()).chain(p.end_direction.iter()).all(|v| v.is_finite()), "{p:?}");
    assert!(p.covariance.iter().flatten().all(|v| v.is_finite()) && p.end_confidence.is_finite());
    let (de, da) = ((p.centre - sc.truth.centre).norm(), axis_angle(&p.axis, &sc.truth.axis).to_degrees());
    eprintln!("{name}: converged {} error {:.1} mm {:.2} deg, {}/{} inliers, failure {:?}", p.converged, de * 1e3, da, p.residuals.inliers, p.residuals.count, p.failure);
    if p.converged {
        assert!(de < 0.03 && da < 3.0, "{name}: converged {:.1} mm / {da:.2} deg from the truth", de * 1e3);
    } else {
        assert!(!p.failure.as_ref().expect("a failure reason").message.is_empty());
    }
    p
}

#[test]
fn tube_cut_by_the_image_border_converges_or_is_flagged() {
    let model = default_model();
    let cam0 = camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    for k in 0..2 {
        let (truth, up, gd) = random_truth(&mut rng, &model, &cam0, (0.9, 1.3));
        // Shift the principal point so that the tube centre lands 15 px inside the right
        // (k = 0) or bottom (k = 1) border: about half the tube is outside the image.
        let u = cam0.project(&nalgebra::Point3::from(truth.centre)).unwrap();
        let mut cam = cam0.clone();
        if k == 0 {
            cam.cx += cam.width as f64 - 15.0 - u.x;
        } else {
            cam.cy += cam.height as f64 - 15.0 - u.y;
        }
        let sc = render(&model, &cam, truth, up, gd, None, 900 + k, 0.01);
        converges_or_is_flagged(&format!("border {k}"), &sc, 40 + k);
    }
}

/// A tube at 0.9-1.2 m with a rock between the camera and its seal end that hides about a
/// third of it, and the same scene without the rock.
fn rock_hides_the_seal_end() -> (Scene, Scene) {
    let model = default_model();
    let cam = camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let (truth, up, gd) = random_truth(&mut rng, &model, &cam, (0.9, 1.2));
    let end = truth.centre + truth.axis * 0.06;
    let rock = (end * (1.0 - 0.15 / end.norm()), 0.03);
    (render(&model, &cam, truth, up, gd, Some(rock), 555, 0.01), render(&model, &cam, truth, up, gd, None, 555, 0.01))
}

#[test]
fn partly_occluded_tube_converges_or_is_flagged() {
    let (sc, _) = rock_hides_the_seal_end();
    let truth = sc.truth;
    converges_or_is_flagged("occluded", &sc, 50);
    // With the depth map the occluded contour samples are left out.
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene { depth: Some((&sc.depth, &sc.camera)), stereo_points: &[], ground: None, mask: None, image_axis: None, shown: None } };
    let mut rng = ChaCha8Rng::seed_from_u64(50);
    let st = perturb(&mut rng, &sc.truth, 0.003, 2.0);
    let p = refiner.refine_seed(&input, &Seed { state: st, end_known: false }, 0, 1.0, None);
    let (de, da) = ((p.centre - truth.centre).norm(), axis_angle(&p.axis, &truth.axis).to_degrees());
    eprintln!("occluded with depth: converged {} error {:.1} mm {:.2} deg, failure {:?}", p.converged, de * 1e3, da, p.failure);
    assert!(p.centre.iter().chain(p.axis.iter()).all(|v| v.is_finite()));
    assert!(!p.converged || de < 0.03 && da < 3.0, "{:.1} mm {da:.2} deg", de * 1e3);
    assert!(p.converged || p.failure.is_some());
}

/// Mask-agreement mode (`Scene::mask`) with a perfect mask: seeds off by 10 mm / 5 degrees
/// converge back. The mask boundary is quantized to whole pixels (±0.5 px per sample), averaged
/// over ~100 silhouette samples.
#[test]
fn mask_agreement_seeds_off_by_10mm_5deg_converge_back() {
    let model = default_model();
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let cam = camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let mut e = Errors { pos: vec![], ang: vec![], end_ok: 0, failed: 0, seed_pos: vec![], seed_ang: vec![] };
    for i in 0..6 {
        let (truth, up, gd) = random_truth(&mut rng, &model, &cam, (0.8, 1.6));
        let sc = render(&model, &cam, truth, up, gd, None, 21_000 + i, 0.01);
        let mask = tube_mask(&model, &sc);
        let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene { depth: None, stereo_points: &[], ground: None, mask: Some((&mask, &sc.camera)), image_axis: None, shown: None } };
        let seed_state = perturb(&mut rng, &truth, 0.010, 5.0);
        e.seed_pos.push((seed_state.c - truth.centre).norm());
        e.seed_ang.push(axis_angle(&seed_state.a, &truth.axis).to_degrees());
        let p = refiner.refine_seed(&input, &Seed { state: seed_state, end_known: false }, 0, 1.0, None);
        assert!(p.centre.iter().chain(p.axis.iter()).all(|v| v.is_finite()));
        if !p.converged {
            e.failed += 1;
            continue;
        }
        e.pos.push((p.centre - truth.centre).norm());
        e.ang.push(axis_angle(&p.axis, &truth.axis).to_degrees());
        e.end_ok += (p.end_direction.dot(&truth.axis) > 0.0) as usize;
    }
    let (pm, _, am, _) = report("mask 10 mm / 5 deg", &mut e);
    assert!(e.failed <= 1, "{} failed", e.failed);
    // Each limb line from ~50 samples of ±0.5 px quantization is placed to ~0.05 px; on a
    // ~40 px wide tube at ~1.2 m a 0.1 px width error is ~3 mm of depth and 0.05 px over a
    // ~300 px long tube ~0.01 degrees: allow 3 mm and 0.5 degrees (median).
    assert!(pm < 0.003, "median position error {pm}");
    assert!(am < 0.5, "median axis error {am}");
}

/// A mask seed whose fit lands on a tube the mask does not cover (the mask lies 0.6 tube
/// widths beside the rendered tube): the fitted silhouette disagrees with the mask, so the seed's centre and
/// axis are kept and flagged; with the check off (`mask_seed_min_agreement = 0`) the fit is
/// returned as is.
#[test]
fn mask_seed_whose_fit_disagrees_with_its_mask_keeps_the_seed() {
    use tubeloc_core::{AxisSeed, DetectionSource, Rle, TubeDetection};
    let (sc, _) = one_scene();
    let model = default_model();
    let truth_mask = tube_mask(&model, &sc);
    // Image direction of the axis, and the unit normal to it.
    let cam = &sc.camera;
    let p0 = cam.project(&nalgebra::Point3::from(sc.truth.centre)).unwrap();
    let p1 = cam.project(&nalgebra::Point3::from(sc.truth.centre + sc.truth.axis * 0.05)).unwrap();
    let d = (p1 - p0).normalize();
    let width = AxisSeed::from_pixels((0..truth_mask.height).flat_map(|y| (0..truth_mask.width).map(move |x| (x, y))).filter(|&(x, y)| truth_mask.get(x, y)).map(|(x, y)| (x as f64, y as f64))).unwrap().width_px;
    let (nx, ny) = (-d.y * 0.6 * width, d.x * 0.6 * width);
    let shifted = tubeloc_core::BinaryMask::from_fn(truth_mask.width, truth_mask.height, |x, y| {
        let (sx, sy) = ((x as f64 - nx).round(), (y as f64 - ny).round());
        sx >= 0.0 && sy >= 0.0 && (sx as usize) < truth_mask.width && (sy as usize) < truth_mask.height && truth_mask.get(sx as usize, sy as usize)
    });
    let pixels: Vec<(f64, f64)> = (0..shifted.height).flat_map(|y| (0..shifted.width).map(move |x| (x, y))).filter(|&(x, y)| shifted.get(x, y)).map(|(x, y)| (x as f64, y as f64)).collect();
    let mut det = TubeDetection::new(0, 0.9, shifted.bbox(), DetectionSource::Learned);
    det.axis_seed = AxisSeed::from_pixels(pixels.iter().copied());
    det.mask = Some(Rle::from_mask(&shifted));
    let g = tubeloc_refine::GroundPlane { normal: sc.ground_n, offset: sc.ground_d };
    let input = RefineInput { image: &sc.image, camera: cam, ground: Some(g), scene: FitScene::default() };
    let seed = tubeloc_refine::seed_from_detection(&det, cam, &model, Some(&g), &[]).unwrap();

    let off = Refiner::new(&tubeloc_core::TubeModel::default(), config(|c| c.mask.min_agreement = 0.0)).unwrap();
    let fit = off.refine(&input, &det, None);
    assert!(fit.converged && fit.seed_kept.is_none(), "{:?}", fit.failure);
    assert!((fit.centre - seed.state.c).norm() > 0.005, "the fit stayed at the seed; the test needs it to move to the tube");

    let on = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let kept = on.refine(&input, &det, None);
    assert!(kept.converged, "{:?}", kept.failure);
    let why = kept.seed_kept.as_deref().expect("seed kept");
    assert!(why.contains("IoU"), "{why}");
    assert!((kept.centre - seed.state.c).norm() < 1e-12);
    assert!(axis_angle(&kept.axis, &seed.state.a) < 1e-9);
    // The covariance says the position is uncertain by at least the fit-to-seed difference.
    let var: f64 = (0..3).map(|i| kept.covariance[i][i]).sum();
    assert!(var.sqrt() >= 0.99 * (fit.centre - seed.state.c).norm(), "covariance {var}");
}

/// The scene's grey rendering coloured like the real tube: the pixels of `mask` gold on the
/// seal section (or, `gold_at_seal` false, on the same length at the foot end) and white-ish
/// elsewhere, scaled by the rendered shading; the ground sand-coloured. RGB bytes.
fn painted(sc: &Scene, model: &tubeloc_refine::CylinderModel, mask: &tubeloc_core::BinaryMask, gold_at_seal: bool) -> Vec<u8> {
    let t = sc.truth;
    let (w, h) = (sc.camera.width as usize, sc.camera.height as usize);
    let seal_z0 = model.sections.last().unwrap().z0;
    let mut rgb = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            let v = sc.image.get(x, y).clamp(0.0, 1.0);
            let r = sc.camera.unproject(&nalgebra::Point2::new(x as f64, y as f64));
            let z = (r.dot(&t.axis) * r.dot(&t.centre) - r.dot(&r) * t.centre.dot(&t.axis)) / (r.dot(&r) - r.dot(&t.axis).powi(2));
            let gold = if gold_at_seal { z >= seal_z0 } else { z <= -seal_z0 };
            let tint: [f32; 3] = match (mask.get(x, y), gold) {
                (false, _) => [1.0, 0.85, 0.7],
                (true, true) => [1.0, 0.8, 0.3],
                (true, false) => [1.0, 1.0, 0.98],
            };
            rgb.extend(tint.iter().map(|k| (255.0 * v * k) as u8));
        }
    }
    rgb
}

/// The colour end decision: a template seed that points the wrong way round (seal end
/// claimed at the foot) on an image where the seal section is gold and the body white comes
/// back with the true seal end and a high confidence; painted the other way round (gold at the
/// foot), the colours, not the edges, decide the end.
#[test]
fn colours_decide_the_seal_end_of_a_flipped_template_seed() {
    use tubeloc_core::{DetectionSource, Pose, TubeDetection};
    use tubeloc_refine::seal_end::ColourImage;
    let (sc, _) = one_scene();
    let model = default_model();
    let t = sc.truth;
    let (w, h) = (sc.camera.width as usize, sc.camera.height as usize);
    let mask = tube_mask(&model, &sc);
    // A template pose with the ends swapped (a half turn about x turns +z around).
    let flip = nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let true_rot = nalgebra::Rotation3::rotation_between(&Vector3::z(), &t.axis).unwrap();
    let mut det = TubeDetection::new(0, 0.9, mask.bbox(), DetectionSource::Line2d);
    det.t_cam_tube = Some(Pose::from_parts(true_rot * flip, t.centre));
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene::default() };
    for gold_at_seal in [true, false] {
        let rgb = painted(&sc, &model, &mask, gold_at_seal);
        let colour = ColourImage { width: w, height: h, rgb: &rgb };
        let p = refiner.refine(&input, &det, Some(&colour));
        assert!(p.converged, "{:?}", p.failure);
        let expected = if gold_at_seal { 1.0 } else { -1.0 };
        assert!(p.end_direction.dot(&t.axis) * expected > 0.99, "gold at the seal: {gold_at_seal}; end {:?}, truth {:?}", p.end_direction, t.axis);
        assert!(p.end_confidence > 0.9, "end confidence {}", p.end_confidence);
        assert!(axis_angle(&p.axis, &t.axis).to_degrees() < 1.5 && (p.centre - t.centre).norm() < 0.02, "axis {:.2} deg, centre {:.1} mm", axis_angle(&p.axis, &t.axis).to_degrees(), (p.centre - t.centre).norm() * 1e3);
    }
}

/// A mask seed has no end of its own: its image axis pointing to the foot is turned toward the
/// gold seal section before the fit, so the fit is exactly the one from the axis pointing the
/// right way, with the true seal end; with the turn disabled the wrong-way seed is fitted as
/// it comes.
#[test]
fn mask_seed_is_turned_toward_the_gold_end_before_the_fit() {
    use tubeloc_core::{AxisSeed, TubeDetection};
    use tubeloc_refine::seal_end::ColourImage;
    let (sc, _) = one_scene();
    let model = default_model();
    let t = sc.truth;
    let mask = tube_mask(&model, &sc);
    let rgb = painted(&sc, &model, &mask, true);
    let colour = ColourImage { width: mask.width, height: mask.height, rgb: &rgb };
    let base = mask_detection(&mask);
    let ax = base.axis_seed.unwrap();
    // The image direction toward the seal end, and the seeds pointing along and against it.
    let p0 = sc.camera.project(&nalgebra::Point3::from(t.centre)).unwrap();
    let p1 = sc.camera.project(&nalgebra::Point3::from(t.centre + t.axis * 0.05)).unwrap();
    let sign = if (p1 - p0).dot(&nalgebra::Vector2::from(ax.direction_px)) >= 0.0 { 1.0 } else { -1.0 };
    let seed_toward = |s: f64| TubeDetection { axis_seed: Some(AxisSeed { direction_px: [s * sign * ax.direction_px[0], s * sign * ax.direction_px[1]], ..ax }), ..base.clone() };
    let g = tubeloc_refine::GroundPlane { normal: sc.ground_n, offset: sc.ground_d };
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: Some(g), scene: FitScene::default() };
    let on = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let right = on.refine(&input, &seed_toward(1.0), Some(&colour));
    let turned = on.refine(&input, &seed_toward(-1.0), Some(&colour));
    assert!(right.converged && turned.converged, "{:?} {:?}", right.failure, turned.failure);
    assert_eq!((turned.centre, turned.axis, turned.end_direction), (right.centre, right.axis, right.end_direction));
    assert!(turned.end_direction.dot(&t.axis) > 0.99, "end {:?}, truth {:?}", turned.end_direction, t.axis);
    // The seed it starts from (what `tubeloc refine --seeds-out` writes) is the turned one;
    // without colours, the detection's own.
    let seed_of = |det: &TubeDetection| tubeloc_refine::seed_from_detection(det, &sc.camera, &model, Some(&g), &[]).unwrap().state;
    let started = on.seed(&input, &seed_toward(-1.0), Some(&colour)).unwrap().state;
    assert_eq!((started.c, started.a), (seed_of(&seed_toward(1.0)).c, seed_of(&seed_toward(1.0)).a));
    let grey_start = on.seed(&input, &seed_toward(-1.0), None).unwrap().state;
    assert_eq!((grey_start.c, grey_start.a), (seed_of(&seed_toward(-1.0)).c, seed_of(&seed_toward(-1.0)).a));
    assert!(grey_start.a.dot(&started.a) < -0.99);
    // Disabled, the seed pointing the wrong way starts the fit (whatever it then decides).
    let off = Refiner::new(&tubeloc_core::TubeModel::default(), config(|c| c.mask.end_colour_corr = 2.0)).unwrap();
    let as_given = off.refine(&input, &seed_toward(-1.0), Some(&colour));
    assert!(as_given.centre != right.centre || as_given.axis != right.axis, "the wrong-way seed gave the same fit without the turn: the test shows nothing");
}

#[test]
fn correlated_stereo_points_widen_the_covariance_not_the_fit() {
    let (sc, pts) = one_scene();
    let t = sc.truth;
    let refine = |k: f64, stereo: &[nalgebra::Point3<f64>]| {
        let cfg = config(|c| c.solver.stereo_points_per_measurement = k);
        let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), cfg).unwrap();
        let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene { depth: None, stereo_points: stereo, ground: None, mask: None, image_axis: None, shown: None } };
        refiner.refine_seed(&input, &Seed { state: AxisState { c: t.centre, a: t.axis }, end_known: true }, 0, 1.0, None)
    };
    let (one, many) = (refine(1.0, &pts), refine(63.0, &pts));
    assert!(one.converged && many.converged);
    assert_eq!((one.centre, one.axis), (many.centre, many.axis), "the fit weighs every point either way");
    // Dividing the stereo information by 63 widens the centre's sigma (stereo fixes the depth)...
    assert!(many.centre_std_m() > 1.5 * one.centre_std_m(), "{} vs {}", many.centre_std_m(), one.centre_std_m());
    // ...but not beyond the fit without stereo points, whose depth only the image constrains.
    let mono = refine(63.0, &[]);
    assert_eq!(refine(1.0, &[]).covariance, mono.covariance, "no stereo points: nothing to scale");
    assert!(many.centre_std_m() <= mono.centre_std_m() * 1.05, "{} vs mono {}", many.centre_std_m(), mono.centre_std_m());
    assert_eq!(config(|c| c.solver.stereo_points_per_measurement = 0.5).validate().unwrap_err().to_string(), "refine config: solver.stereo_points_per_measurement = 0.5 is out of range [1, 10000]");
}

/// `solver.axis_sigma_scale` k widens the axis's σ by k in the output covariance (D Σ D with
/// D = diag(1, 1, 1, k, k)) and changes nothing else: not the fit, not the centre's block.
#[test]
fn axis_sigma_scale_widens_the_axis_covariance_not_the_fit() {
    let (sc, pts) = one_scene();
    let t = sc.truth;
    let refine = |k: f64| {
        let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), config(|c| c.solver.axis_sigma_scale = k)).unwrap();
        let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene { stereo_points: &pts, ..FitScene::default() } };
        refiner.refine_seed(&input, &Seed { state: AxisState { c: t.centre, a: t.axis }, end_known: true }, 0, 1.0, None)
    };
    let (one, wide) = (refine(1.0), refine(1.5));
    assert!(one.converged && wide.converged, "{:?} {:?}", one.failure, wide.failure);
    assert_eq!((one.centre, one.axis, one.end_direction), (wide.centre, wide.axis, wide.end_direction), "the fit does not depend on it");
    assert!(one.axis_std_rad() > 0.0);
    assert!((wide.axis_std_rad() / one.axis_std_rad() - 1.5).abs() < 1e-9, "{} vs {}", wide.axis_std_rad(), one.axis_std_rad());
    for i in 0..5 {
        for j in 0..5 {
            let k = [i, j].iter().filter(|&&m| m >= 3).count() as i32;
            let want = one.covariance[i][j] * 1.5f64.powi(k);
            assert!((wide.covariance[i][j] - want).abs() <= 1e-12 * want.abs().max(1e-30), "entry {i},{j}: {} vs {want}", wide.covariance[i][j]);
        }
    }
    assert_eq!(wide.centre_std_m(), one.centre_std_m());
    assert_eq!(config(|c| c.solver.axis_sigma_scale = 0.9).validate().unwrap_err().to_string(), "refine config: solver.axis_sigma_scale = 0.9 is out of range [1, 100]");
}

#[test]
fn stereo_polish_keeps_the_stereo_distance_over_a_lower_ground() {
    // The tube lies 20 mm above the given ground plane (terrain relief over the nominal ground).
    // Settings that re-place mono tubes at the ground's height (as mask seeds use) must not
    // move a stereo fit there: its distance comes from the stereo points.
    let (sc, pts) = one_scene();
    let t = sc.truth;
    let cfg = config(|c| {
        c.priors.ground_height_known = false;
        c.seeds.explicit.ground_relief_sigma_m = 0.001;
    });
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), cfg).unwrap();
    let ground = tubeloc_refine::GroundPlane { normal: sc.ground_n, offset: sc.ground_d - 0.020 };
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: Some(ground), scene: FitScene { depth: None, stereo_points: &pts, ground: None, mask: None, image_axis: None, shown: None } };
    let p = refiner.refine_seed(&input, &Seed { state: AxisState { c: t.centre, a: t.axis }, end_known: true }, 0, 1.0, None);
    assert!(p.converged, "{:?}", p.failure);
    let err = (p.centre - t.centre).norm();
    assert!(err < 0.004, "centre {:.1} mm off the truth (pulled toward the ground?)", err * 1e3);
}

/// Mismatched stereo points (here: every point 10 m away along its pixel's ray, as SGM gives
/// beside the left border) put a mask seed's distance there and support no fit: the detection
/// is refined as if there were none (mono with the ground plane), not left converged far away.
#[test]
fn mask_seed_with_mismatched_stereo_points_falls_back_to_mono() {
    let (sc, _) = one_scene();
    let model = default_model();
    let mask = tube_mask(&model, &sc);
    let det = mask_detection(&mask);
    let pixels: Vec<(f64, f64)> = (0..mask.height).flat_map(|y| (0..mask.width).map(move |x| (x, y))).filter(|&(x, y)| mask.get(x, y)).map(|(x, y)| (x as f64, y as f64)).collect();
    let cam = &sc.camera;
    let junk: Vec<nalgebra::Point3<f64>> = pixels.iter().map(|&(x, y)| nalgebra::Point3::from(cam.unproject(&nalgebra::Point2::new(x, y)).normalize() * 10.0)).collect();
    let g = tubeloc_refine::GroundPlane { normal: sc.ground_n, offset: sc.ground_d };
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let with_junk = RefineInput { image: &sc.image, camera: cam, ground: Some(g), scene: FitScene { depth: None, stereo_points: &junk, ground: None, mask: None, image_axis: None, shown: None } };
    let without = RefineInput { scene: FitScene::default(), ..with_junk };
    let (a, b) = (refiner.refine(&with_junk, &det, None), refiner.refine(&without, &det, None));
    assert!(b.converged, "{:?}", b.failure);
    assert_eq!((a.centre, a.axis, a.converged), (b.centre, b.axis, b.converged), "the mono pose, not one at 10 m");
    assert_eq!(a.residuals.stereo_points, 0);
    assert!((a.centre - sc.truth.centre).norm() < 0.05, "{:.3} m off", (a.centre - sc.truth.centre).norm());
}

/// The mask's axis line is a prior on the fitted axis's image direction
/// (`mask.axis_sigma_px`): with a mask axis turned 1 degree in the image, a tight
/// prior keeps the fit on the mask's line, no prior lets the edges bring it back to the truth,
/// and the default (0.4 px) lets the edges of this clean, fully visible tube win. With stereo
/// points and the ground plane the stereo edge polish takes the prior too; without a ground
/// plane it is not used.
#[test]
fn mask_axis_prior_holds_the_image_direction_by_its_sigma() {
    let (sc, pts) = one_scene();
    let model = default_model();
    let mask = tube_mask(&model, &sc);
    let mut det = mask_detection(&mask);
    let mut ax = det.axis_seed.unwrap();
    let turn = 1f64.to_radians();
    let [dx, dy] = ax.direction_px;
    ax.direction_px = [dx * turn.cos() - dy * turn.sin(), dx * turn.sin() + dy * turn.cos()];
    let mask_dir = nalgebra::Vector2::new(ax.direction_px[0], ax.direction_px[1]);
    det.axis_seed = Some(ax);
    let cam = &sc.camera;
    let g = tubeloc_refine::GroundPlane { normal: sc.ground_n, offset: sc.ground_d };
    let input = RefineInput { image: &sc.image, camera: cam, ground: Some(g), scene: FitScene::default() };
    // Image direction of a pose's axis at its centre, and its angle to a unit image direction.
    let image_angle = |c: Vector3<f64>, a: Vector3<f64>, d: &nalgebra::Vector2<f64>| {
        let p0 = cam.project(&nalgebra::Point3::from(c)).unwrap();
        let p1 = cam.project(&nalgebra::Point3::from(c + a * 0.01)).unwrap();
        (p1 - p0).normalize().dot(d).abs().min(1.0).acos().to_degrees()
    };
    let p0 = cam.project(&nalgebra::Point3::from(sc.truth.centre)).unwrap();
    let true_dir = (cam.project(&nalgebra::Point3::from(sc.truth.centre + sc.truth.axis * 0.01)).unwrap() - p0).normalize();
    let refine = |sigma_px: f64| Refiner::new(&tubeloc_core::TubeModel::default(), config(|c| c.mask.axis_sigma_px = sigma_px)).unwrap().refine(&input, &det, None);
    let tight = refine(0.02);
    assert!(tight.converged, "{:?}", tight.failure);
    assert!(image_angle(tight.centre, tight.axis, &mask_dir) < 0.3, "tight prior: {:.2} deg off the mask's line", image_angle(tight.centre, tight.axis, &mask_dir));
    for sigma_px in [0.0, RefineConfig::default().mask.axis_sigma_px] {
        let p = refine(sigma_px);
        assert!(p.converged, "{:?}", p.failure);
        let off = image_angle(p.centre, p.axis, &true_dir);
        assert!(off < 0.5, "sigma {sigma_px} px: {off:.2} deg off the true image axis");
        assert!(axis_angle(&p.axis, &sc.truth.axis).to_degrees() < 0.5);
    }
    let with_points = |ground: Option<tubeloc_refine::GroundPlane>, sigma_px: f64| {
        let input = RefineInput { image: &sc.image, camera: cam, ground, scene: FitScene { stereo_points: &pts, ..FitScene::default() } };
        let p = Refiner::new(&tubeloc_core::TubeModel::default(), config(|c| c.mask.axis_sigma_px = sigma_px)).unwrap().refine(&input, &det, None);
        assert!(p.converged && p.residuals.stereo_points > 0, "{:?}", p.failure);
        p
    };
    let polished = with_points(Some(g), 0.02);
    assert!(image_angle(polished.centre, polished.axis, &mask_dir) < 0.3, "stereo + ground, tight prior: {:.2} deg off the mask's line", image_angle(polished.centre, polished.axis, &mask_dir));
    let (a, b) = (with_points(None, 0.02), with_points(None, 0.0));
    assert_eq!((a.centre, a.axis), (b.centre, b.axis), "no ground plane: the prior is not used");
}

/// A mask seed of a tube a rock partly hides (the mask shows only the tube's visible pixels):
/// in mono, the contour points outside the mask grown by `mask_visibility_px` are hidden, so
/// fewer contour samples are fitted than with the check off, none of them on the rock, and
/// the fit stays on the tube.
#[test]
fn mask_seed_leaves_out_the_contour_its_mask_does_not_show() {
    let model = default_model();
    let (sc, clear) = rock_hides_the_seal_end();
    let truth = sc.truth;
    let mask = tube_mask(&model, &sc);
    let full = tube_mask(&model, &clear);
    let (shown, whole) = (mask.area() as f64, full.area() as f64);
    assert!(shown < 0.85 * whole, "the rock hides {:.0} % of the tube", 100.0 * (1.0 - shown / whole));
    let det = mask_detection(&mask);
    let g = tubeloc_refine::GroundPlane { normal: sc.ground_n, offset: sc.ground_d };
    let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: Some(g), scene: FitScene::default() };
    let refine = |px: usize| Refiner::new(&tubeloc_core::TubeModel::default(), config(|c| c.mask.visibility_px = px)).unwrap().refine(&input, &det, None);
    let (on, off) = (refine(RefineConfig::default().mask.visibility_px), refine(0));
    for (name, p) in [("mask visibility", &on), ("off", &off)] {
        eprintln!("{name}: converged {} {:.2} deg, centre {:.1} mm off, {} of {} samples inliers", p.converged, axis_angle(&p.axis, &truth.axis).to_degrees(), (p.centre - truth.centre).norm() * 1e3, p.residuals.inliers, p.residuals.count);
    }
    // Without the check the rock's outline is fitted too, and most samples miss the tube's
    // edges (here the fit is rejected as empty terrain).
    assert!(on.converged, "{:?}", on.failure);
    assert!((on.residuals.count as f64) < 0.6 * off.residuals.count as f64, "samples fitted: {} with the mask's visibility, {} without", on.residuals.count, off.residuals.count);
    assert!(on.residuals.inliers as f64 > 0.6 * on.residuals.count as f64, "{} of {} inliers", on.residuals.inliers, on.residuals.count);
    assert!(axis_angle(&on.axis, &truth.axis).to_degrees() < 1.0, "{:.2} deg", axis_angle(&on.axis, &truth.axis).to_degrees());
    // Across the axis the mask seed sits on the tube (along it, the hidden part leaves the
    // centre free: the CLI's hidden-end anchoring is stereo's).
    let d = on.centre - truth.centre;
    let perp = (d - truth.axis * d.dot(&truth.axis)).norm();
    assert!(perp < 0.01, "{:.1} mm across the axis", perp * 1e3);
}

/// `solver.fine_polish` (the narrow tubes' full-resolution stage run again with the fine
/// search) acts on mono fits only: with stereo points the poses are bit-identical with it on
/// or off, and in mono it changes the fits of narrow tubes (fitted at full resolution alone).
#[test]
fn fine_polish_changes_mono_fits_and_leaves_stereo_ones_alone() {
    let model = default_model();
    let with = Refiner::new(&tubeloc_core::TubeModel::default(), config(|c| c.solver.fine_polish = true)).unwrap();
    let without = Refiner::new(&tubeloc_core::TubeModel::default(), config(|c| c.solver.fine_polish = false)).unwrap();
    let cam = camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let (mut mono_changed, mut stereo_compared) = (0, 0);
    for i in 0..4 {
        let (truth, up, gd) = random_truth(&mut rng, &model, &cam, (2.0, 3.0));
        let sc = render(&model, &cam, truth, up, gd, None, 31_000 + i, 0.01);
        let seed = Seed { state: perturb(&mut rng, &truth, 0.010, 5.0), end_known: false };
        let pts = stereo_points(&model, &sc, 4, 0.25, 0.2, i);
        for (stereo, points) in [(false, &[][..]), (true, &pts[..])] {
            let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene { stereo_points: points, ..FitScene::default() } };
            let (a, b) = (with.refine_seed(&input, &seed, 0, 1.0, None), without.refine_seed(&input, &seed, 0, 1.0, None));
            let same = a.centre == b.centre && a.axis == b.axis && a.converged == b.converged;
            if stereo {
                assert!(same, "scene {i}: stereo pose changed by the fine polish: {:?} vs {:?}", a.centre, b.centre);
                stereo_compared += 1;
            } else {
                mono_changed += (!same) as usize;
            }
        }
    }
    assert_eq!(stereo_compared, 4);
    assert!(mono_changed >= 1, "the fine polish changed no mono fit of a narrow tube");
}

/// A Line2D template pose on a ground plane (`seeds.template_as_image_axis`): the
/// nearest template view puts the tube at the right pixel but at the template's distance and
/// tilt. Seeded by its image axis, placed on the ground, the fit lands on the tube; from the
/// template pose itself it keeps much of the distance error.
#[test]
fn template_poses_on_the_ground_are_seeded_by_their_image_axis() {
    use nalgebra::Rotation3;
    use tubeloc_core::{DetectionSource, Pose, Rle, TubeDetection};
    let model = default_model();
    let cam = camera(false);
    let refiner = |on: bool| Refiner::new(&tubeloc_core::TubeModel::default(), config(|c| c.seeds.template_as_image_axis = on)).unwrap();
    let (with, without) = (refiner(true), refiner(false));
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let (mut on, mut off) = (vec![], vec![]);
    for i in 0..6 {
        let (truth, up, gd) = random_truth(&mut rng, &model, &cam, (1.5, 2.5));
        let sc = render(&model, &cam, truth, up, gd, None, 41_000 + i, 0.01);
        // The template: the same pixel 8 % further away, the axis turned by 6 degrees.
        let c = truth.centre * 1.08;
        let turn = Unit::new_normalize(Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)));
        let a = Rotation3::from_axis_angle(&turn, 6f64.to_radians()) * truth.axis;
        let rot = Rotation3::rotation_between(&Vector3::z(), &a).unwrap();
        let mask = tube_mask(&model, &sc);
        let mut det = TubeDetection::new(0, 0.9, mask.bbox(), DetectionSource::Line2d);
        det.t_cam_tube = Some(Pose::from_parts(rot, c));
        det.mask = Some(Rle::from_mask(&mask));
        for (r, errs) in [(&with, &mut on), (&without, &mut off)] {
            let p = r.refine(&sc.ground_input(), &det, None);
            assert!(p.centre.iter().all(|v| v.is_finite()));
            errs.push(if p.converged { (p.centre - truth.centre).norm() } else { f64::INFINITY });
        }
    }
    let (m_on, _) = med_p90(&mut on);
    let (m_off, _) = med_p90(&mut off);
    eprintln!("template seeds on the ground: centre error median {:.1} mm by the image axis, {:.1} mm from the template pose", m_on * 1e3, m_off * 1e3);
    assert!(m_on < 0.005, "median centre error {m_on} m from the image axis");
    assert!(m_on < 0.5 * m_off, "image axis {m_on} m vs template pose {m_off} m");
}
