//! SGM accuracy on synthetic pairs with exact disparity, region mode and error handling.

use tubeloc_core::Plane;
use tubeloc_stereo::synthetic::{bench_scene, render_scene, SyntheticBox};
use tubeloc_stereo::{disparity, disparity_regions, Paths, Roi, SgmParams, StereoError};

/// (bad fraction over visible pixels, invalid counted bad; mean abs error over estimated).
fn errors(est: &Plane<f32>, gt: &Plane<f32>, vis: &Plane<u8>, t: f32, margin: usize) -> (f64, f64) {
    let (mut n, mut bad, mut sum, mut m) = (0, 0, 0.0f64, 0);
    for y in margin..est.height - margin {
        for x in margin..est.width - margin {
            if vis.get(x, y) == 0 {
                continue;
            }
            n += 1;
            let e = est.get(x, y);
            if e.is_nan() {
                bad += 1;
                continue;
            }
            let err = (e - gt.get(x, y)).abs();
            sum += err as f64;
            m += 1;
            if err > t {
                bad += 1;
            }
        }
    }
    (bad as f64 / n as f64, sum / m as f64)
}

#[test]
fn slanted_plane_with_boxes_is_recovered_with_eight_and_four_paths() {
    let pair = render_scene(320, 240, (8.0, 0.04, 0.02), &[SyntheticBox { x0: 150.0, y0: 60.0, x1: 230.0, y1: 150.0, d: 40.5 }], 7);
    for paths in [Paths::Eight, Paths::Four] {
        let p = SgmParams { num_disparities: 64, paths, ..SgmParams::default() };
        let d = disparity(&pair.left, &pair.right, &p).unwrap();
        let (bad1, mae) = errors(&d, &pair.disparity, &pair.visible, 1.0, 4);
        eprintln!("{paths:?}: bad-1.0 {bad1:.4}, MAE {mae:.3} px");
        assert!(bad1 < 0.04, "{paths:?}: bad-1.0 = {bad1}");
        assert!(mae < 0.25, "{paths:?}: MAE = {mae}");
        // The box's inner pixels carry its disparity to sub-pixel accuracy.
        let inner = d.get(190, 100);
        assert!((inner - 40.5).abs() < 0.3, "box disparity {inner}");
    }
}

#[test]
fn same_seed_gives_same_images_and_disparities() {
    let a = bench_scene(160, 120, 3);
    let b = bench_scene(160, 120, 3);
    assert_eq!(a.left, b.left);
    assert_eq!(a.right, b.right);
    assert_ne!(a.left, bench_scene(160, 120, 4).left);
}

#[test]
fn region_mode_matches_full_image_inside_the_region() {
    let pair = render_scene(256, 192, (10.0, 0.02, 0.0), &[SyntheticBox { x0: 120.0, y0: 60.0, x1: 180.0, y1: 120.0, d: 30.0 }], 11);
    let p = SgmParams { num_disparities: 48, ..SgmParams::default() };
    let full = disparity(&pair.left, &pair.right, &p).unwrap();
    let roi = Roi::new(130, 70, 40, 40);
    let reg = disparity_regions(&pair.left, &pair.right, &p, &[roi], 16).unwrap();
    let (mut agree, mut n) = (0, 0);
    for y in 70..110 {
        for x in 130..170 {
            n += 1;
            let (a, b) = (full.get(x, y), reg.get(x, y));
            if (a - b).abs() < 0.5 {
                agree += 1;
            }
            assert!((b - 30.0).abs() < 1.0 || b.is_nan(), "({x},{y}) = {b}");
        }
    }
    assert!(agree as f64 / n as f64 > 0.97, "{agree}/{n}");
    // Outside the grown region nothing is computed.
    assert!(reg.get(10, 10).is_nan() && reg.get(250, 190).is_nan());
}

#[test]
fn bad_inputs_give_clear_errors() {
    let a = Plane::<u8>::new(64, 48);
    let b = Plane::<u8>::new(64, 40);
    let e = disparity(&a, &b, &SgmParams::default()).unwrap_err();
    assert!(matches!(e, StereoError::SizeMismatch { .. }));
    assert!(e.to_string().contains("64x48") && e.to_string().contains("64x40"), "{e}");
    let e = disparity(&a, &a, &SgmParams { num_disparities: 20, ..SgmParams::default() }).unwrap_err().to_string();
    assert!(e.contains("num_disparities") && e.contains("multiple of 16"), "{e}");
    let e = disparity(&a, &a, &SgmParams { p1: 50, p2: 10, ..SgmParams::default() }).unwrap_err().to_string();
    assert!(e.contains("p1"), "{e}");
    let p = SgmParams { num_disparities: 16, ..SgmParams::default() };
    let e = disparity_regions(&a, &a, &p, &[], 4).unwrap_err().to_string();
    assert!(e.contains("no regions"), "{e}");
    let e = disparity_regions(&a, &a, &p, &[Roi::new(5, 5, 0, 10)], 4).unwrap_err().to_string();
    assert!(e.contains("empty"), "{e}");
}
