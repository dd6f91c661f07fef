//! Matching and whole pose evaluations with known answers.

use nalgebra::{Rotation3, Vector3};
use tubeloc_core::{CameraModel, Pose, TubeModel};
use tubeloc_eval::pose_bop::ModelPoints;
use tubeloc_eval::pose_match::{match_by_centre_distance, match_by_iou, match_by_mask_iou, MatchMethod, TubeEstimate, TubeTruth};
use tubeloc_eval::pose_summary::{evaluate_poses, percentile, summarize, PoseEvalConfig, PoseEvaluation};

fn pose(x: f64, y: f64, z: f64) -> Pose {
    Pose::from_parts(Rotation3::from_euler_angles(1.4, 0.2, 0.7), Vector3::new(x, y, z))
}

fn shifted(p: &Pose, d: Vector3<f64>) -> Pose {
    Pose::from_parts(Rotation3::from_matrix_unchecked(p.rotation()), p.translation() + d)
}

#[test]
fn percentiles_and_fractions() {
    let v: Vec<f64> = (1..=10).map(f64::from).collect();
    assert_eq!(percentile(&v, 50.0), Some(5.5));
    assert!((percentile(&v, 90.0).unwrap() - 9.1).abs() < 1e-12);
    assert_eq!(percentile(&[], 50.0), None);
    let s = summarize(&[3.0, 1.0, f64::NAN, 7.0, 12.0], &[2.0, 5.0, 10.0]);
    assert_eq!(s.count, 4);
    assert_eq!(s.median, Some(5.0));
    assert_eq!(s.max, Some(12.0));
    let f: Vec<f64> = s.within.iter().map(|w| w.fraction).collect();
    assert_eq!(f, vec![0.25, 0.5, 0.75]);
    assert_eq!(summarize(&[], &[1.0]).median, None);
}

#[test]
fn greedy_matching_by_distance_and_by_iou() {
    let truths = vec![TubeTruth { image_id: 1, pose: pose(0.0, 0.0, 1.0) }, TubeTruth { image_id: 1, pose: pose(0.3, 0.0, 1.0) }, TubeTruth { image_id: 2, pose: pose(0.0, 0.0, 1.0) }];
    let est = |img, p: Pose, score| TubeEstimate { image_id: img, pose: p, score, std: None };
    let estimates = vec![
        // Low score, closest to truth 0, but truth 0 is taken first and truth 1 is beyond the gate.
        est(1, pose(0.004, 0.0, 1.0), 0.2),
        // High score, near truth 0 too: takes truth 0 first.
        est(1, pose(0.01, 0.0, 1.0), 0.9),
        // Same place as truth 2 but another image: false positive in image 3.
        est(3, pose(0.0, 0.0, 1.0), 0.5),
    ];
    let m = match_by_centre_distance(&truths, &estimates, 0.05);
    assert_eq!(m.pairs.len(), 1);
    assert_eq!((m.pairs[0].estimate, m.pairs[0].truth), (1, 0));
    assert!((m.pairs[0].similarity - 0.01).abs() < 1e-12);
    assert_eq!(m.unmatched_estimates, vec![0, 2]);
    assert_eq!(m.unmatched_truths, vec![1, 2]);
    assert!(m.method.to_string().contains("nearest 3D centre within 50.0 mm"));

    // IoU matrix [estimate][truth].
    let iou = [[0.2, 0.8, 0.0], [0.4, 0.6, 0.0], [0.0, 0.0, 0.0]];
    let m = match_by_iou(&truths, &estimates, 0.5, |e, t| iou[e][t]);
    // Estimate 1 (score 0.9) goes first and takes truth 1 (0.6); estimate 0 is then left with truth 0 (0.2 < 0.5).
    assert_eq!(m.pairs.iter().map(|p| (p.estimate, p.truth)).collect::<Vec<_>>(), vec![(1, 1)]);
    assert_eq!(m.method, MatchMethod::MaskIou { min_iou: 0.5 });
    assert!(m.method.to_string().contains("mask IoU >= 0.5"));
}

#[test]
fn evaluation_recalls_and_summaries_match_hand_computation() {
    let t0 = pose(0.0, 0.0, 1.0);
    let t1 = pose(0.2, 0.1, 1.5);
    let t2 = pose(-0.1, 0.0, 0.8);
    let truths = vec![TubeTruth { image_id: 7, pose: t0 }, TubeTruth { image_id: 7, pose: t1 }, TubeTruth { image_id: 8, pose: t2 }];
    let estimates = vec![
        TubeEstimate { image_id: 7, pose: t0, score: 0.9, std: None },                                          // exact
        TubeEstimate { image_id: 7, pose: shifted(&t1, Vector3::new(0.0, 0.0, 0.010)), score: 0.8, std: None }, // 10 mm off
        TubeEstimate { image_id: 8, pose: pose(0.5, 0.5, 3.0), score: 0.7, std: None },                         // far: false positive
    ];
    let m = match_by_centre_distance(&truths, &estimates, 0.05);
    assert_eq!(m.pairs.len(), 2);
    let model = ModelPoints::from_tube(&TubeModel::default(), 0.003).unwrap();
    let cfg = PoseEvalConfig { default_camera: Some(CameraModel::from_hfov(640, 480, 60.0)), ..Default::default() };
    let ev = evaluate_poses(&truths, &estimates, &m, &model, &cfg).unwrap();
    assert_eq!((ev.n_truths, ev.n_estimates, ev.n_matched), (3, 3, 2));
    // MSSD of the 10 mm shift is 10 mm: correct at every threshold (>= 0.1 d ≈ 15 mm) but the
    // first (0.05 d ≈ 7.6 mm); the exact one everywhere; the third truth is a miss.
    assert!((ev.bop.diameter_mm - 151.6).abs() < 0.3, "{}", ev.bop.diameter_mm);
    let want = (1.0 / 3.0 + 9.0 * 2.0 / 3.0) / 10.0;
    assert!((ev.bop.ar_mssd - want).abs() < 1e-12, "{}", ev.bop.ar_mssd);
    assert!((ev.bop.ar_mssd_flip - want).abs() < 1e-12);
    assert!((ev.summaries.mssd_mm.median.unwrap() - 5.0).abs() < 1e-9);
    assert!((ev.summaries.centre_distance_mm.max.unwrap() - 10.0).abs() < 1e-9);
    assert!(ev.bop.ar_mspd.is_some() && ev.bop.mspd_recalls.len() == 10);
    assert_eq!(ev.end_correct_fraction, 1.0);
    assert!(ev.method.contains("3D centre"));
    // Serializes and reads back.
    let text = serde_json::to_string(&ev).unwrap();
    let back: PoseEvaluation = serde_json::from_str(&text).unwrap();
    assert_eq!(back.n_matched, 2);
    assert_eq!(back.bop.ar_mssd, ev.bop.ar_mssd);

    // Without a camera MSPD is absent rather than made up.
    let ev = evaluate_poses(&truths, &estimates, &m, &model, &PoseEvalConfig::default()).unwrap();
    assert_eq!(ev.bop.ar_mspd, None);
    assert!(ev.pairs.iter().all(|p| p.mspd_px.is_none()));
}

#[test]
fn mask_iou_matching_uses_core_rle() {
    use tubeloc_core::{BinaryMask, Rle, TubeAxisPose};
    let rect = |x0: usize, x1: usize| Rle::from_mask(&BinaryMask::from_fn(20, 10, |x, y| x >= x0 && x < x1 && (2..8).contains(&y)));
    let truths = vec![TubeTruth { image_id: 1, pose: pose(0.0, 0.0, 1.0) }, TubeTruth { image_id: 1, pose: pose(0.2, 0.0, 1.0) }];
    let axis = TubeAxisPose::new(1, 0.9, Vector3::new(0.2, 0.0, 1.0), Vector3::new(0.0, 1.0, 0.0), 0.8).unwrap();
    let estimates = vec![TubeEstimate::from_axis_pose(&axis), TubeEstimate { image_id: 1, pose: pose(0.0, 0.0, 1.0), score: 0.5, std: None }];
    // Truth masks: columns 0..8 and 10..18. Estimate 0 covers 10..16 (IoU 6/8 with truth 1),
    // estimate 1 covers 4..8 (IoU 4/8 with truth 0: below a 0.6 gate, at a 0.5 gate).
    let tm = vec![rect(0, 8), rect(10, 18)];
    let em = vec![rect(10, 16), rect(4, 8)];
    let m = match_by_mask_iou(&truths, &estimates, &tm, &em, 0.6).unwrap();
    assert_eq!(m.pairs.len(), 1);
    assert_eq!((m.pairs[0].estimate, m.pairs[0].truth), (0, 1));
    assert!((m.pairs[0].similarity - 0.75).abs() < 1e-12);
    assert_eq!(m.unmatched_estimates, vec![1]);
    let m = match_by_mask_iou(&truths, &estimates, &tm, &em, 0.5).unwrap();
    assert_eq!(m.pairs.len(), 2);
    assert!(match_by_mask_iou(&truths, &estimates, &tm[..1], &em, 0.5).unwrap_err().to_string().contains("1 truth masks for 2 truths"));
}

#[test]
fn covariance_consistency_divides_each_error_by_the_estimates_sigma() {
    use tubeloc_core::TubeAxisPose;
    // Truth: tube along camera x at (0, 0, 2). Estimate: 10 mm off along y, axis turned 1 deg
    // about z, with a covariance saying σ_centre = 5 mm and σ_axis = 0.5 deg: errors of 2 σ.
    let truth = TubeAxisPose::new(1, 1.0, Vector3::new(0.0, 0.0, 2.0), Vector3::x(), 0.9).unwrap();
    let turned = Rotation3::from_axis_angle(&Vector3::z_axis(), 1f64.to_radians()) * Vector3::x();
    let mut est = TubeAxisPose::new(1, 0.9, Vector3::new(0.0, 0.010, 2.0), turned, 0.9).unwrap();
    let (sc, sa) = (0.005f64, 0.5f64.to_radians());
    for i in 0..3 {
        est.covariance[i][i] = sc * sc / 3.0;
    }
    for i in 3..5 {
        est.covariance[i][i] = sa * sa / 2.0;
    }
    let truths = vec![TubeTruth { image_id: 1, pose: truth.to_pose() }];
    let plain = TubeEstimate { std: None, ..TubeEstimate::from_axis_pose(&est) };
    let estimates = [TubeEstimate::from_axis_pose(&est), plain];
    let model = ModelPoints::from_tube(&TubeModel::default(), 0.005).unwrap();
    for (k, want) in [(0, Some(2.0)), (1, None)] {
        let m = match_by_centre_distance(&truths, &estimates[k..=k], 0.05);
        let ev = evaluate_poses(&truths, &estimates[k..=k], &m, &model, &PoseEvalConfig::default()).unwrap();
        let p = &ev.pairs[0];
        match want {
            Some(z) => {
                assert!((p.axis_error_over_std.unwrap() - z).abs() < 1e-6, "{:?}", p.axis_error_over_std);
                // Centre distance 10 mm over 5 mm.
                assert!((p.centre_error_over_std.unwrap() - z).abs() < 1e-6, "{:?}", p.centre_error_over_std);
                let s = &ev.summaries.axis_error_over_std;
                assert_eq!((s.count, s.within[0].fraction, s.within[1].fraction), (1, 0.0, 1.0));
            }
            None => {
                assert_eq!((p.axis_error_over_std, p.centre_error_over_std), (None, None));
                assert_eq!(ev.summaries.centre_error_over_std.count, 0);
            }
        }
    }
}
