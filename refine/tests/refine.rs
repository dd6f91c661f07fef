//! End-to-end refinement on rendered scenes with exact ground truth.

mod common;

use common::*;
use nalgebra::{Rotation3, Unit, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tubeloc_core::tube_pose::axis_angle;
use tubeloc_core::FailureReason;
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
}

fn run_batch(n: usize, seed: u64, stereo: bool, distorted: bool) -> Errors {
    let model = default_model();
    let refiner = Refiner::new(&tubeloc_core::TubeModel::default(), RefineConfig::default()).unwrap();
    let cam = camera(distorted);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut e = Errors { pos: vec![], ang: vec![], end_ok: 0, failed: 0 };
    for i in 0..n {
        let (truth, up, gd) = random_truth(&mut rng, &model, &cam, (0.8, 1.6));
        let sc = render(&model, &cam, truth, up, gd, None, seed * 1000 + i as u64, 0.01);
        let pts = if stereo { stereo_points(&model, &sc, 4, 0.25, 0.2, i as u64) } else { vec![] };
        let input = RefineInput { image: &sc.image, camera: &sc.camera, ground: None, scene: FitScene { depth: None, stereo_points: &pts } };
        let seed_state = perturb(&mut rng, &truth, 0.01, 4.0);
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

#[test]
fn mono_perturbed_seeds_converge_back() {
    let mut e = run_batch(8, 11, false, false);
    let (pm, p9) = med_p90(&mut e.pos);
    let (am, a9) = med_p90(&mut e.ang);
    eprintln!("mono: position median {:.2} mm p90 {:.2} mm; axis median {:.3} deg p90 {:.3} deg; end ok {}/{}; failed {}", pm * 1e3, p9 * 1e3, am, a9, e.end_ok, e.pos.len(), e.failed);
    assert!(e.failed <= 1);
    assert!(pm < 0.010, "median position error {pm}");
    assert!(am < 0.5, "median axis error {am}");
}
