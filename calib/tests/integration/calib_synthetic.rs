//! Rig calibration on synthetic calibration sets with known truth (corners only, fast).

use nalgebra::{Point2, Point3};
use tubeloc_calib::{calibrate, load_calib_set, CalibError, CalibrationInput, CalibrationOptions, CameraSpec, CornerSource, Observation};
use tubeloc_synth::calib_set::{default_rig, generate, write_calib_set, BoardLayout, CalibSetConfig};

fn make_set(views: usize, noise: f64, seed: u64) -> (tempfile::TempDir, tubeloc_calib::LoadedSet) {
    let cfg = CalibSetConfig { views, seed, corner_noise_px: noise, render: false, scale: 0.25, ..Default::default() };
    let set = generate(&default_rig(), &BoardLayout::default_board(), &cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_calib_set(dir.path(), &set, || {}).unwrap();
    let loaded = load_calib_set(dir.path(), CornerSource::Noisy, None).unwrap();
    (dir, loaded)
}

#[test]
fn four_camera_rig_recovers_truth() {
    let noise = 0.2;
    let (_dir, set) = make_set(36, noise, 11);
    let cal = calibrate(&set.input, &CalibrationOptions::default()).unwrap();
    for (c, t) in cal.cameras.iter().zip(&set.truth.cameras) {
        let (m, tm) = (&c.model, &t.model);
        let (efx, efy) = ((m.fx - tm.fx).abs() / tm.fx, (m.fy - tm.fy).abs() / tm.fy);
        let (ecx, ecy) = ((m.cx - tm.cx).abs(), (m.cy - tm.cy).abs());
        eprintln!("{}: fx {:.3} (true {:.3}, rel err {:.2e}) fy rel err {:.2e}, cx err {ecx:.3} px, cy err {ecy:.3} px, rms {:.3} px, views {}, outliers {}", c.name, m.fx, tm.fx, efx, efy, c.rms_px, c.views.len(), c.outliers);
        assert!(efx < 1e-3 && efy < 1e-3, "{}: focal error {efx} {efy}", c.name);
        assert!(ecx < 1.0 && ecy < 1.0, "{}: principal point error {ecx} {ecy}", c.name);
    }
    for (l, r, b) in &cal.baselines {
        let truth = set.truth.baseline(l, r).unwrap();
        eprintln!("baseline {l}-{r}: {b:.5} m (true {truth:.5}), error {:.3} mm", (b - truth).abs() * 1e3);
        assert!((b - truth).abs() < 0.5e-3, "{l}-{r}: {b} vs {truth}");
    }
    eprintln!("overall rms {:.4} px per corner, {:.4} px per coordinate (added noise {noise})", cal.rms_px, cal.rms_coord_px);
    assert!((cal.rms_coord_px - noise).abs() < 0.15 * noise, "rms per coordinate {} vs noise {noise}", cal.rms_coord_px);
}

#[test]
fn outliers_are_rejected() {
    let (_dir, mut set) = make_set(15, 0.1, 5);
    // Keep one camera, corrupt 1% of its corners by 8 px.
    set.input.observations.retain(|o| o.camera == 1);
    let mut n = 0;
    for o in &mut set.input.observations {
        for (i, p) in o.image.iter_mut().enumerate() {
            if i % 97 == 3 {
                p.x += 8.0;
                n += 1;
            }
        }
    }
    set.input.cameras = vec![set.input.cameras[1].clone()];
    for o in &mut set.input.observations {
        o.camera = 0;
    }
    set.input.stereo_pairs.clear();
    let cal = calibrate(&set.input, &CalibrationOptions::default()).unwrap();
    let c = &cal.cameras[0];
    let t = &set.truth.cameras[1].model;
    assert!(c.outliers >= n && c.outliers <= n + 5, "{} outliers rejected, {n} planted", c.outliers);
    assert!((c.model.fx - t.fx).abs() / t.fx < 1e-3);
    assert!(cal.rms_coord_px < 0.15);
}

fn planar_view(camera: usize, view: usize, pts: &[(f64, f64)], img: impl Fn(f64, f64) -> (f64, f64)) -> Observation {
    Observation {
        camera,
        view,
        object: pts.iter().map(|&(x, y)| Point3::new(x, y, 0.0)).collect(),
        image: pts
            .iter()
            .map(|&(x, y)| {
                let (u, v) = img(x, y);
                Point2::new(u, v)
            })
            .collect(),
    }
}

#[test]
fn degenerate_inputs_give_clear_errors() {
    let spec = CameraSpec { name: "A".into(), width: 640, height: 480 };
    let grid: Vec<(f64, f64)> = (0..20).map(|i| ((i % 5) as f64 * 0.05, (i / 5) as f64 * 0.05)).collect();
    let proj = |s: f64| move |x: f64, y: f64| (320.0 + 500.0 * x / (1.0 + s * x), 240.0 + 500.0 * y / (1.0 + s * y));
    // Too few views.
    let input = CalibrationInput { cameras: vec![spec.clone()], observations: vec![planar_view(0, 0, &grid, proj(0.1)), planar_view(0, 1, &grid, proj(0.2))], stereo_pairs: vec![] };
    let e = calibrate(&input, &CalibrationOptions::default()).unwrap_err();
    assert!(matches!(e, CalibError::TooFew(_)) && e.to_string().contains("2 usable views"), "{e}");
    // Collinear corners: the views are skipped and named, leaving too few.
    let line: Vec<(f64, f64)> = (0..10).map(|i| (i as f64 * 0.03, i as f64 * 0.01)).collect();
    let input = CalibrationInput { cameras: vec![spec.clone()], observations: (0..4).map(|v| planar_view(0, v, &line, proj(0.1))).collect(), stereo_pairs: vec![] };
    let e = calibrate(&input, &CalibrationOptions::default()).unwrap_err().to_string();
    assert!(e.contains("collinear") && e.contains("view 0"), "{e}");
    // Two cameras that never see the board at the same time: extrinsics undetermined.
    let (_dir, set) = make_set(12, 0.1, 3);
    let mut input = set.input.clone();
    input.observations.retain(|o| o.camera == 0 || o.camera == 3);
    for o in &mut input.observations {
        if o.camera == 3 {
            o.view += 1000;
        }
    }
    let keep = [input.cameras[0].clone(), input.cameras[3].clone()];
    input.cameras = keep.to_vec();
    for o in &mut input.observations {
        o.camera = if o.camera == 3 { 1 } else { 0 };
    }
    input.stereo_pairs.clear();
    let e = calibrate(&input, &CalibrationOptions::default()).unwrap_err().to_string();
    assert!(e.contains("shares no simultaneous view"), "{e}");
}

/// Corners detected in a rendered set (two images at once, each on its own detector) equal
/// those detected one image at a time, lie within a pixel of the exact ones, and the progress
/// callback is called once per image with their number.
#[test]
fn detected_corners_match_the_exact_ones_whatever_the_threads() {
    let cfg = CalibSetConfig { views: 3, seed: 5, render: true, scale: 0.25, ..Default::default() };
    let set = generate(&default_rig(), &BoardLayout::default_board(), &cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_calib_set(dir.path(), &set, || {}).unwrap();
    let exact = load_calib_set(dir.path(), CornerSource::Exact, None).unwrap();
    let calls = std::sync::Mutex::new(Vec::new());
    let two = tubeloc_calib::DetectorConfig { threads: 2, ..Default::default() };
    let detected = tubeloc_calib::load_calib_set_reporting(dir.path(), CornerSource::Detect, Some(&two), &|n| calls.lock().unwrap().push(n)).unwrap();
    let one = load_calib_set(dir.path(), CornerSource::Detect, Some(&tubeloc_calib::DetectorConfig::default())).unwrap();
    let images = set.views.iter().flat_map(|v| &v.observations).filter(|o| o.image.is_some()).count();
    assert_eq!(calls.into_inner().unwrap(), vec![images; images]);
    assert_eq!(format!("{:?}", detected.input.observations), format!("{:?}", one.input.observations));
    let (mut compared, mut detected_corners) = (0, 0);
    for d in &detected.input.observations {
        let e = exact.input.observations.iter().find(|e| e.camera == d.camera && e.view == d.view).unwrap();
        for (p, q) in d.object.iter().zip(&d.image) {
            detected_corners += 1;
            // The set writes exact corners only for tags facing the camera, 2 px inside the
            // image; one nearer the border or more oblique can still be detected.
            let Some(i) = e.object.iter().position(|o| o == p) else { continue };
            assert!((q - e.image[i]).norm() < 1.0, "view {} camera {}: {q} vs {}", d.view, d.camera, e.image[i]);
            compared += 1;
        }
    }
    assert!(compared >= 16 && compared * 10 >= detected_corners * 9, "{compared} of {detected_corners} detected corners have exact ones");
    let missing = tubeloc_calib::load_calib_set(dir.path(), CornerSource::Detect, None).unwrap_err().to_string();
    assert!(missing.contains("needs a detector"), "{missing}");
}
