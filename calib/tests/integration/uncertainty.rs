//! Parameter uncertainties of the rig calibration (from the Schur-complement factorization):
//! they shrink as views are added, agree with the spread of the estimates over seeded noise
//! trials, and stay defined when k3 is held at zero.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use tubeloc_calib::{calibrate, load_calib_set, CalibrationInput, CalibrationOptions, CornerSource, RigCalibration};
use tubeloc_synth::calib_set::{default_rig, generate, write_calib_set, BoardLayout, CalibSetConfig};

/// The exact corners of a 24-view set, restricted to the first `cameras` cameras.
fn exact_input(cameras: usize) -> CalibrationInput {
    let cfg = CalibSetConfig { views: 24, seed: 21, corner_noise_px: 0.0, render: false, scale: 0.25, ..Default::default() };
    let set = generate(&default_rig(), &BoardLayout::default_board(), &cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_calib_set(dir.path(), &set, || {}).unwrap();
    let mut input = load_calib_set(dir.path(), CornerSource::Exact, None).unwrap().input;
    input.cameras.truncate(cameras);
    input.observations.retain(|o| o.camera < cameras);
    let names: Vec<&str> = input.cameras.iter().map(|c| c.name.as_str()).collect();
    input.stereo_pairs.retain(|(l, r)| names.contains(&l.as_str()) && names.contains(&r.as_str()));
    input
}

/// `input` with Gaussian noise of `sigma` px on every corner coordinate.
fn noisy(input: &CalibrationInput, sigma: f64, seed: u64) -> CalibrationInput {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, sigma).unwrap();
    let mut out = input.clone();
    for o in &mut out.observations {
        for p in &mut o.image {
            p.x += n.sample(&mut rng);
            p.y += n.sample(&mut rng);
        }
    }
    out
}

fn spread(xs: &[f64]) -> f64 {
    let mean = xs.iter().sum::<f64>() / xs.len() as f64;
    (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (xs.len() - 1) as f64).sqrt()
}

#[test]
fn uncertainties_shrink_as_views_are_added() {
    let all = noisy(&exact_input(1), 0.3, 3);
    let mut few = all.clone();
    few.observations.retain(|o| o.view < 6);
    let (a, b) = (calibrate(&few, &CalibrationOptions::default()).unwrap(), calibrate(&all, &CalibrationOptions::default()).unwrap());
    let (sa, sb) = (a.cameras[0].std, b.cameras[0].std);
    eprintln!("std with 6 views {sa:?}\nstd with 24 views {sb:?}");
    for j in 0..9 {
        assert!(sa[j] > 0.0 && sb[j] > 0.0, "parameter {j}: std must be positive");
        assert!(sb[j] < 0.8 * sa[j], "parameter {j}: 24 views give std {} vs 6 views {}", sb[j], sa[j]);
    }
}

#[test]
fn uncertainties_match_the_spread_over_noise_trials() {
    // Two cameras (L40, L20) over 24 views; 30 trials of 0.3 px corner noise.
    let exact = exact_input(2);
    let trials: Vec<RigCalibration> = (0..30).map(|t| calibrate(&noisy(&exact, 0.3, 100 + t), &CalibrationOptions::default()).unwrap()).collect();
    let mut checked = Vec::new();
    for c in 0..2 {
        for (j, name) in ["fx", "fy", "cx", "cy", "k1"].iter().enumerate() {
            let values: Vec<f64> = trials.iter().map(|r| [r.cameras[c].model.fx, r.cameras[c].model.fy, r.cameras[c].model.cx, r.cameras[c].model.cy, r.cameras[c].model.distortion.k1][j]).collect();
            let reported = trials.iter().map(|r| r.cameras[c].std[j]).sum::<f64>() / trials.len() as f64;
            checked.push((format!("camera {c} {name}"), spread(&values), reported));
        }
    }
    for axis in 0..3 {
        let values: Vec<f64> = trials.iter().map(|r| r.cameras[1].t_rig_cam.translation()[axis]).collect();
        let reported = trials.iter().map(|r| r.cameras[1].t_rig_cam_std.translation_m[axis]).sum::<f64>() / trials.len() as f64;
        checked.push((format!("camera 1 position axis {axis}"), spread(&values), reported));
    }
    assert!(trials.iter().all(|r| r.cameras[0].t_rig_cam_std == Default::default()), "the first camera defines the rig frame: zero uncertainty");
    for (what, empirical, reported) in &checked {
        let ratio = reported / empirical;
        eprintln!("{what}: empirical spread {empirical:.3e}, reported std {reported:.3e}, ratio {ratio:.2}");
        // 30 trials: the sample spread itself is uncertain by about 13 % (one sigma).
        assert!((0.6..1.6).contains(&ratio), "{what}: reported std {reported:.3e} vs empirical spread {empirical:.3e}");
    }
}

#[test]
fn fixed_k3_leaves_the_other_uncertainties_defined() {
    let input = noisy(&exact_input(1), 0.3, 5);
    let cal = calibrate(&input, &CalibrationOptions { fix_k3: true, ..Default::default() }).unwrap();
    let c = &cal.cameras[0];
    assert_eq!(c.model.distortion.k3, 0.0);
    assert_eq!(c.std[8], 0.0, "k3 is held: no uncertainty");
    assert!(c.std[..8].iter().all(|s| *s > 0.0 && s.is_finite()), "{:?}", c.std);
}
