//! The pipeline on rendered scenes: `Locator::locate` returns the rendered tube, mono with a
//! ground plane and with a stereo pair.

#[path = "../../refine/tests/integration/common/mod.rs"]
#[allow(clippy::too_many_arguments)]
mod common;

use image::{DynamicImage, GrayImage, Luma};
use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tubeloc_core::{DetectionSource, Plane, Pose, Rig, RigCamera, TubeDetection};
use tubeloc_pipeline::{CameraSelection, ExternalDetections, GroundPlane, LocateInput, Locator, LocatorSettings, PipelineError, TubeDetector};

fn to_image(p: &Plane<f32>) -> DynamicImage {
    DynamicImage::ImageLuma8(GrayImage::from_fn(p.width as u32, p.height as u32, |x, y| Luma([(p.get(x as usize, y as usize).clamp(0.0, 1.0) * 255.0).round() as u8])))
}

fn rig(cam: &tubeloc_core::CameraModel, baseline: f64) -> Rig {
    let right = Pose::from_parts(nalgebra::Rotation3::identity(), Vector3::new(baseline, 0.0, 0.0));
    Rig { cameras: vec![RigCamera { name: "L".into(), model: cam.clone(), t_rig_cam: Pose::identity() }, RigCamera { name: "R".into(), model: cam.clone(), t_rig_cam: right }], stereo_pairs: vec![("L".into(), "R".into())] }
}

fn angle_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.normalize().dot(&b.normalize()).abs().min(1.0).acos().to_degrees()
}

#[test]
fn locate_returns_the_rendered_tube_mono_and_stereo() {
    let model = common::default_model();
    let cam = common::camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (truth, up, gd) = common::random_truth(&mut rng, &model, &cam, (1.2, 1.6));
    let baseline = 0.05;
    let left = common::render(&model, &cam, truth, up, gd, None, 11, 0.01);
    let right = common::render_right(&model, &cam, truth, up, gd, 11, 0.01, baseline);
    let mask = common::tube_mask(&model, &left);
    let det: TubeDetection = common::mask_detection(&mask);
    assert_eq!(det.source, DetectionSource::Learned);
    let (li, ri) = (to_image(&left.image), to_image(&right.image));
    let ground = GroundPlane::new(up, gd).unwrap();
    let locator = Locator::new(&rig(&cam, baseline), &CameraSelection::default(), Box::new(ExternalDetections::new(vec![det], "test")), LocatorSettings::default()).unwrap();
    assert_eq!(locator.camera().name, "L");

    // Mono with the ground plane.
    let mono = locator.locate(&LocateInput { image: &li, right: None, ground: Some(ground), up: None, ignore: None }).unwrap();
    assert_eq!((mono.tubes.len(), mono.rejected.len()), (1, 0));
    let t = &mono.tubes[0];
    let (dc, da) = ((t.pose.centre - truth.centre).norm(), angle_deg(&t.pose.axis, &truth.axis));
    assert!(dc < 0.02 && da < 2.0, "mono: centre {:.1} mm, axis {da:.2} deg off", dc * 1e3);
    assert_eq!(mono.up_cam, ground.normal);
    assert_eq!(mono.timings.fit_ms.len(), 1);
    // The grasp frame: origin at the centre, +x along the axis, approach against up.
    assert!((t.t_cam_grasp.translation() - t.pose.centre).norm() < 1e-12);
    let r = t.t_cam_grasp.rotation();
    assert!(r.column(0).dot(&t.pose.axis).abs() > 1.0 - 1e-9 && r.column(2).dot(&ground.normal) < 0.0);
    // On a clean scene the plain grasp from above is free: checked against the ground plane
    // (mono: no terrain) and chosen unchanged, with the fingertips above the ground.
    let g = &t.grasp;
    assert!(g.feasible && !g.changed && !g.terrain_checked && g.candidates_tried > 1 && g.clearance_mm >= 1.0, "{g:?}");
    assert_eq!(g.t_cam_grasp, t.t_cam_grasp);
    assert!(!mono.terrain_checked);
    let json = serde_json::to_value(t).unwrap();
    assert_eq!(json["grasp"]["feasible"], serde_json::json!(true), "{json}");

    // Stereo: the pair's points and the stereo stages.
    let st = locator.locate(&LocateInput { image: &li, right: Some(&ri), ground: Some(ground), up: None, ignore: None }).unwrap();
    assert_eq!(st.tubes.len(), 1);
    let t = &st.tubes[0];
    let (dc, da) = ((t.pose.centre - truth.centre).norm(), angle_deg(&t.pose.axis, &truth.axis));
    assert!(t.pose.residuals.stereo_points > 0, "no stereo points");
    assert!(dc < 0.01 && da < 1.0, "stereo: centre {:.1} mm, axis {da:.2} deg off", dc * 1e3);
    // Stereo checks the grasp against the terrain around the tube too; the scene is clean.
    let g = &t.grasp;
    assert!(g.feasible && g.terrain_checked && st.terrain_checked && g.rejected.terrain == 0 && g.clearance_mm >= 1.0, "{g:?}");
    assert_eq!(g.t_cam_grasp, t.t_cam_grasp);

    // `refine` with the same detections gives the poses `locate` refined, before merging.
    let (poses, fit_ms) = locator.refine(&LocateInput { image: &li, right: None, ground: Some(ground), up: None, ignore: None }, &mono.detections).unwrap();
    assert_eq!(fit_ms.len(), 1);
    assert_eq!(poses[0], mono.tubes[0].pose);
    // The overlay tells a located tube (green, with its gripper) from a converged fit that was
    // rejected (yellow, no gripper), so a rejected tube never looks handed to the planner.
    let count = |img: &image::RgbImage, c: [u8; 3]| img.pixels().filter(|p| p.0 == c).count();
    use tubeloc_pipeline::overlay::{GRASP_FEASIBLE, LOCATED, REJECTED_CONVERGED};
    let shown = locator.overlay_located(&li, &mono);
    assert!(count(&shown, LOCATED) > 50 && count(&shown, REJECTED_CONVERGED) == 0);
    assert!(count(&shown, GRASP_FEASIBLE) > 0, "the feasible grasp's gripper is not drawn");
    let mut low = mono.clone();
    let tube = low.tubes.remove(0);
    low.rejected.push(tubeloc_pipeline::RejectedTube { tube, reason: tubeloc_pipeline::Rejection::LowProbability { probability: 0.1, threshold: 0.8 } });
    let shown = locator.overlay_located(&li, &low);
    assert!(count(&shown, LOCATED) == 0 && count(&shown, REJECTED_CONVERGED) > 50);
}

/// The rendered scene of one tube at 1.2-1.6 m (seed 5) on its ground: the camera, the image,
/// the ground plane and the tube's detection (its exact mask).
fn one_tube_scene() -> (tubeloc_core::CameraModel, DynamicImage, GroundPlane, TubeDetection) {
    let model = common::default_model();
    let cam = common::camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (truth, up, gd) = common::random_truth(&mut rng, &model, &cam, (1.2, 1.6));
    let left = common::render(&model, &cam, truth, up, gd, None, 11, 0.01);
    let det: TubeDetection = common::mask_detection(&common::tube_mask(&model, &left));
    let image = to_image(&left.image);
    let ground = GroundPlane::new(up, gd).unwrap();
    (cam, image, ground, det)
}

/// A tube whose centre falls in the ignore mask is listed as `in_ignored_region` at its
/// centre's pixel, with the pose it would have had; a mask elsewhere changes nothing; a mask
/// of another size is refused.
#[test]
fn a_tube_centred_in_the_ignore_mask_is_not_handed_over() {
    let (cam, image, ground, det) = one_tube_scene();
    let locator = Locator::new(&rig(&cam, 0.05), &CameraSelection::default(), Box::new(ExternalDetections::new(vec![det], "test")), LocatorSettings::default()).unwrap();
    let input = |ignore| LocateInput { image: &image, right: None, ground: Some(ground), up: None, ignore };
    let plain = locator.locate(&input(None)).unwrap();
    assert_eq!(plain.tubes.len(), 1);
    let centre = cam.project(&nalgebra::Point3::from(plain.tubes[0].pose.centre)).unwrap();
    let (w, h) = (cam.width as usize, cam.height as usize);
    let square = |cx: f64, cy: f64, r: f64| Plane { width: w, height: h, data: (0..w * h).map(|i| u8::from(((i % w) as f64 - cx).abs() <= r && ((i / w) as f64 - cy).abs() <= r)).collect() };
    // A small square on the tube's centre.
    let on_centre = square(centre.x, centre.y, 3.0);
    let over = locator.locate(&input(Some(&on_centre))).unwrap();
    assert_eq!((over.tubes.len(), over.rejected.len()), (0, 1));
    let r = &over.rejected[0];
    assert_eq!(r.reason.name(), "in_ignored_region");
    let tubeloc_pipeline::Rejection::InIgnoredRegion { pixel } = r.reason else { panic!("{:?}", r.reason) };
    assert!((pixel.0 - centre.x).abs() < 1e-9 && (pixel.1 - centre.y).abs() < 1e-9, "{pixel:?} vs {centre}");
    assert_eq!(r.tube.pose, plain.tubes[0].pose);
    // The same square 40 px away: the tube is handed over as before.
    let beside = square(centre.x + 40.0, centre.y, 3.0);
    let away = locator.locate(&input(Some(&beside))).unwrap();
    assert_eq!(away.tubes.len(), 1);
    assert_eq!(away.tubes[0].pose, plain.tubes[0].pose);
    // A mask drawn in an image (any channel non-zero ignores the pixel).
    let mut drawn = image::RgbImage::new(cam.width, cam.height);
    drawn.put_pixel(centre.x.round() as u32, centre.y.round() as u32, image::Rgb([0, 0, 1]));
    let m = tubeloc_pipeline::ignore_mask_of(&DynamicImage::ImageRgb8(drawn));
    assert_eq!(m.data.iter().filter(|&&v| v != 0).count(), 1);
    assert_eq!(locator.locate(&input(Some(&m))).unwrap().tubes.len(), 0);
    let small = Plane { width: 10, height: 10, data: vec![0u8; 100] };
    let msg = locator.locate(&input(Some(&small))).unwrap_err().to_string();
    assert!(msg.contains("ignore mask is 10x10") && msg.contains(&format!("{}x{}", cam.width, cam.height)), "{msg}");
}

#[test]
fn wrong_sizes_are_refused_naming_the_detection() {
    let cam = common::camera(false);
    let img = DynamicImage::ImageLuma8(GrayImage::new(cam.width, cam.height));
    let mut det = TubeDetection::new(3, 0.9, [10.0, 10.0, 20.0, 5.0], DetectionSource::External);
    det.mask = Some(tubeloc_core::Rle::from_mask(&tubeloc_core::BinaryMask::new(64, 48)));
    let detector = ExternalDetections::new(vec![det], "results.json");
    assert_eq!(detector.name(), "external");
    let locator = Locator::new(&rig(&cam, 0.2), &CameraSelection::default(), Box::new(detector), LocatorSettings::default()).unwrap();
    let e = locator.locate(&LocateInput::mono(&img)).unwrap_err();
    assert!(matches!(e, PipelineError::Input(_)));
    let msg = e.to_string();
    assert!(msg.contains("results.json") && msg.contains("detection 0") && msg.contains("64x48"), "{msg}");
    // An image that is not the camera's size.
    let small = DynamicImage::ImageLuma8(GrayImage::new(64, 48));
    let msg = locator.locate(&LocateInput::mono(&small)).unwrap_err().to_string();
    assert!(msg.contains("64x48") && msg.contains("\"L\""), "{msg}");
}

/// A camera whose images exceed the stated bound is refused before any image is read, with the
/// size, the bound and the memory it would take.
#[test]
fn cameras_beyond_the_pixel_bound_are_refused_up_front() {
    let cam = tubeloc_core::CameraModel::from_hfov(13000, 13000, 60.0);
    let detector = ExternalDetections::new(vec![], "results.json");
    let e = Locator::new(&rig(&cam, 0.2), &CameraSelection::default(), Box::new(detector), LocatorSettings::default()).err().expect("a 169-megapixel camera is refused");
    let msg = e.to_string();
    assert!(msg.contains("13000x13000") && msg.contains("169 megapixels") && msg.contains("100 megapixels") && msg.contains("GB"), "{msg}");
    // At the bound it is accepted.
    let ok = tubeloc_core::CameraModel::from_hfov(10000, 10000, 60.0);
    assert!(Locator::new(&rig(&ok, 0.2), &CameraSelection::default(), Box::new(ExternalDetections::new(vec![], "r")), LocatorSettings::default()).is_ok());
}

/// A mask seed whose fit kept the detector's seed (`seed_kept`: the fitted silhouette
/// disagreed with a mask too narrow for it) is still snapped, to the silhouette of the pose it
/// returns, when the tube is narrower than `kept_seed_max_width_px`: the segmenter's narrow
/// mask takes the tube's full width. A wider tube's kept seed, or a pose that did not
/// converge, leaves the mask as it is.
#[test]
fn a_kept_seed_is_snapped_to_the_silhouette_of_its_pose() {
    use tubeloc_core::TubeAxisPose;
    use tubeloc_refine::silhouette::{mask_iou, MaskSnap};
    let model = common::default_model();
    let cam = common::camera(false);
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let (truth, up, gd) = common::random_truth(&mut rng, &model, &cam, (1.2, 1.6));
    let scene = common::render(&model, &cam, truth, up, gd, None, 11, 0.01);
    let full = common::tube_mask(&model, &scene);
    // Narrower than the tube, as the segmenter's masks of small grey tubes are: eroded until
    // it covers at most 70 % of the tube.
    let narrow = (1..20).map(|r| full.eroded(r)).find(|m| mask_iou(m, &full) <= 0.7).unwrap();
    let before = mask_iou(&narrow, &full);
    assert!(before > 0.2 && before < 0.8, "narrow mask IoU {before:.3}");
    let locator = Locator::new(&rig(&cam, 0.05), &CameraSelection::default(), Box::new(ExternalDetections::new(vec![], "test")), LocatorSettings::default()).unwrap();
    let mut kept = TubeAxisPose::new(0, 0.5, truth.centre, truth.axis, 0.5).unwrap();
    kept.seed_kept = Some("the fitted silhouette agrees with the detector's mask at IoU 0.45 < 0.6".into());
    // This tube is wider than the default bound of 8 px: its kept seed is left alone.
    let width_px = 2.0 * locator.refiner().model.body_radius() * cam.fx / truth.centre.z;
    assert!(width_px > MaskSnap::default().kept_seed_max_width_px, "tube {width_px:.1} px wide");
    let unchanged = |pose: &TubeAxisPose, snap: &MaskSnap| {
        let mut det = common::mask_detection(&narrow);
        let snapped = tubeloc_pipeline::stages::snapped_detection(&mut det, pose, locator.refiner(), &cam, snap);
        !snapped && mask_iou(&det.mask.as_ref().unwrap().to_mask().unwrap(), &full) == before
    };
    assert!(unchanged(&kept, &MaskSnap::default()));
    // With the bound above its width it is snapped to the kept pose's silhouette.
    let wide_enough = MaskSnap { kept_seed_max_width_px: width_px + 1.0, ..MaskSnap::default() };
    let mut det = common::mask_detection(&narrow);
    assert!(tubeloc_pipeline::stages::snapped_detection(&mut det, &kept, locator.refiner(), &cam, &wide_enough));
    let after = mask_iou(&det.mask.as_ref().unwrap().to_mask().unwrap(), &full);
    assert!(after > 0.9 && after > before + 0.1, "snapped mask IoU {after:.3}, narrow {before:.3}");
    // Not converged: nothing to snap to.
    let failed = kept.clone().fail(tubeloc_core::FailureReason::Diverged, "test");
    assert!(unchanged(&failed, &wide_enough));
}

/// A frame whose tubes, at their expected range, are narrower than the learned detector can
/// enlarge to its working width carries a warning saying so, with the width; a full Navcam
/// frame under the same view does not, nor does a detector without a working scale.
#[test]
fn a_frame_too_coarse_for_the_learned_detector_is_warned_about() {
    let locate = |size: u32, range_m: &str| {
        let (rig, ground) = tubeloc_core::AssumedView::NAVCAM.rig("assumed", size, size).unwrap();
        let detector = tubeloc_pipeline::shipped::learned_detector(None, range_m).unwrap();
        let locator = Locator::new(&rig, &CameraSelection::default(), Box::new(detector), LocatorSettings::default()).unwrap();
        let image = DynamicImage::ImageLuma8(GrayImage::from_fn(size, size, |x, y| Luma([(60 + (x * 7 + y * 13) % 90) as u8])));
        locator.locate(&LocateInput { image: &image, right: None, ground: Some(ground), up: None, ignore: None }).unwrap().warnings
    };
    let coarse = locate(256, "1:4");
    assert_eq!(coarse.len(), 1, "{coarse:?}");
    // 256 px across 45 degrees: f = 309 px; the ground at the image centre is 3.8 m away.
    assert!(coarse[0].contains("about 1.") && coarse[0].contains("under the 4 px"), "{}", coarse[0]);
    assert!(locate(1024, "1:4").is_empty());
    assert!(locate(256, "off").is_empty());
}

/// With the model's pose evidence, a converged tube that passes the score calibration is handed
/// over only where the evidence reaches the floor: the rendered tube at a confident score is,
/// the same tube at a score the evidence calls unlikely is listed as `weak_pose_evidence` with
/// the same pose, and a floor of 0 hands it over again.
#[test]
fn a_tube_with_weak_pose_evidence_is_not_handed_over() {
    let (cam, image, ground, det) = one_tube_scene();
    let evidence = tubeloc_pipeline::shipped::pose_evidence("shipped").unwrap();
    let input = LocateInput { image: &image, right: None, ground: Some(ground), up: None, ignore: None };
    let locate = |score: f64, min: f64| {
        let mut settings = LocatorSettings::default();
        settings.pose_evidence = Some(evidence.clone());
        settings.min_pose_evidence = min;
        let mut d = det.clone();
        d.score = score;
        Locator::new(&rig(&cam, 0.05), &CameraSelection::default(), Box::new(ExternalDetections::new(vec![d], "test")), settings).unwrap().locate(&input).unwrap()
    };
    assert_eq!(LocatorSettings::default().min_pose_evidence, tubeloc_pipeline::settings::DEFAULT_MIN_POSE_EVIDENCE);
    // A clean rendered tube at the detector's confident score: every contour sample on an
    // edge, a sharp axis; the evidence is high and recorded.
    let sure = locate(0.9, tubeloc_pipeline::settings::DEFAULT_MIN_POSE_EVIDENCE);
    assert_eq!((sure.tubes.len(), sure.rejected.len()), (1, 0));
    let e = sure.tubes[0].pose_evidence.expect("a converged tube carries its pose evidence");
    assert!((e - evidence.probability(&sure.tubes[0].pose)).abs() < 1e-12 && e > 0.9, "{e}");
    assert_eq!(serde_json::to_value(&sure.tubes[0]).unwrap()["pose_evidence"], serde_json::json!(e));
    // The same fit at a score of 0.01 (the identity calibration, threshold 0, accepts it): the
    // evidence is its score's as much as the fit's, and falls below the floor.
    let weak = locate(0.01, tubeloc_pipeline::settings::DEFAULT_MIN_POSE_EVIDENCE);
    assert_eq!((weak.tubes.len(), weak.rejected.len()), (0, 1));
    let r = &weak.rejected[0];
    assert_eq!(r.reason.name(), "weak_pose_evidence");
    let tubeloc_pipeline::Rejection::WeakPoseEvidence { evidence: ev, min } = r.reason else { panic!("{:?}", r.reason) };
    assert!(ev < min && min == tubeloc_pipeline::settings::DEFAULT_MIN_POSE_EVIDENCE && Some(ev) == r.tube.pose_evidence, "{ev} {min}");
    assert!((r.tube.pose.centre - sure.tubes[0].pose.centre).norm() < 1e-9, "the score does not move the fit");
    // A floor of 0 hands it over.
    let off = locate(0.01, 0.0);
    assert_eq!((off.tubes.len(), off.rejected.len()), (1, 0));
    // Without pose evidence (the library default), no tube carries one.
    let plain = Locator::new(&rig(&cam, 0.05), &CameraSelection::default(), Box::new(ExternalDetections::new(vec![det.clone()], "test")), LocatorSettings::default()).unwrap().locate(&input).unwrap();
    assert!(plain.tubes.len() == 1 && plain.tubes[0].pose_evidence.is_none());
}

/// `image` with a band of the tube body's width and brightness along the image axis of `pose`,
/// from 0.6 lengths before its foot to 0.6 lengths past its seal end, the tube itself left as
/// it is: a slab rim, as a cylinder fit sees one.
fn with_rim_band(image: &DynamicImage, cam: &tubeloc_core::CameraModel, pose: &tubeloc_core::TubeAxisPose) -> DynamicImage {
    let model = tubeloc_core::TubeModel::default();
    let e0 = cam.project(&nalgebra::Point3::from(pose.centre - pose.axis * model.length / 2.0)).unwrap();
    let e1 = cam.project(&nalgebra::Point3::from(pose.centre + pose.axis * model.length / 2.0)).unwrap();
    let (ell, u) = ((e1 - e0).norm(), (e1 - e0).normalize());
    let half_width = cam.fx * model.body_radius() / pose.centre.z;
    let mut grey = image.to_luma8();
    let body = grey.get_pixel(((e0.x + e1.x) / 2.0) as u32, ((e0.y + e1.y) / 2.0) as u32).0[0];
    for (x, y, p) in grey.enumerate_pixels_mut() {
        let d = nalgebra::Vector2::new(x as f64, y as f64) - e0.coords;
        let (t, a) = (d.dot(&u), d.x * -u.y + d.y * u.x);
        if a.abs() <= half_width && t > -0.6 * ell && t < 1.6 * ell && !(0.0..=ell).contains(&t) {
            p.0[0] = body;
        }
    }
    DynamicImage::ImageLuma8(grey)
}

/// A tube ends where the tube ends: the rendered tube is handed over with a small limb
/// continuation; the same image with a bright band of the tube's width going on past both its
/// ends (a slab rim, as a cylinder fit sees one) is listed as `limbs_continue`, and handed
/// over with the check off.
/// A locator is not built with cuts that cannot mean anything: the error names the field and
/// its value.
#[test]
fn a_locator_refuses_cuts_out_of_their_range() {
    let (cam, _, _, det) = one_tube_scene();
    let build = |s: LocatorSettings| Locator::new(&rig(&cam, 0.05), &CameraSelection::default(), Box::new(ExternalDetections::new(vec![det.clone()], "test")), s).err().map(|e| e.to_string());
    let with = |f: &dyn Fn(&mut LocatorSettings)| {
        let mut s = LocatorSettings::default();
        f(&mut s);
        build(s)
    };
    assert_eq!(with(&|_| {}), None);
    assert_eq!(with(&|s| s.max_limb_continuation = None), None);
    for (f, says) in [
        (&(|s: &mut LocatorSettings| s.max_limb_continuation = Some(-1.0)) as &dyn Fn(&mut LocatorSettings), "max_limb_continuation = -1"),
        (&|s: &mut LocatorSettings| s.max_limb_continuation = Some(f64::NAN), "max_limb_continuation = NaN"),
        (&|s: &mut LocatorSettings| s.min_pose_evidence = 1.5, "min_pose_evidence = 1.5"),
        (&|s: &mut LocatorSettings| s.min_highlight_level = 300.0, "min_highlight_level = 300"),
    ] {
        let e = with(f).unwrap_or_else(|| panic!("{says}: accepted"));
        assert!(e.contains("locator settings") && e.contains(says), "{e}");
    }
}

#[test]
fn a_tube_whose_limbs_go_on_past_its_ends_is_not_handed_over() {
    let (cam, image, ground, det) = one_tube_scene();
    let locate = |image: &DynamicImage, max: Option<f64>| {
        let mut settings = LocatorSettings::default();
        settings.max_limb_continuation = max;
        let input = LocateInput { image, right: None, ground: Some(ground), up: None, ignore: None };
        Locator::new(&rig(&cam, 0.05), &CameraSelection::default(), Box::new(ExternalDetections::new(vec![det.clone()], "test")), settings).unwrap().locate(&input).unwrap()
    };
    let max = tubeloc_pipeline::settings::DEFAULT_MAX_LIMB_CONTINUATION;
    assert_eq!(LocatorSettings::default().max_limb_continuation, Some(max));
    let tube = locate(&image, Some(max));
    assert_eq!((tube.tubes.len(), tube.rejected.len()), (1, 0));
    let c = tube.tubes[0].limb_continuation.expect("a converged tube inside the image carries its limb continuation");
    assert!(c < 0.3, "a rendered tube on ground: {c}");
    assert_eq!(serde_json::to_value(&tube.tubes[0]).unwrap()["limb_continuation"], serde_json::json!(c));
    let rim = with_rim_band(&image, &cam, &tube.tubes[0].pose);
    let r = locate(&rim, Some(max));
    assert_eq!((r.tubes.len(), r.rejected.len()), (0, 1), "{:?}", r.rejected.first().map(|t| &t.reason));
    let tubeloc_pipeline::Rejection::LimbsContinue { continuation, max: m } = r.rejected[0].reason else { panic!("{:?}", r.rejected[0].reason) };
    assert!(continuation > max && m == max && Some(continuation) == r.rejected[0].tube.limb_continuation, "{continuation}");
    assert_eq!(r.rejected[0].reason.name(), "limbs_continue");
    let off = locate(&rim, None);
    assert_eq!((off.tubes.len(), off.rejected.len()), (1, 0));
}

/// Line2D's pose verification with a limb cut sets a candidate whose limbs go on past its ends
/// aside (`LimbsContinue`) and keeps it where they end; without the cut it is kept either way.
#[test]
fn pose_verification_sets_aside_a_candidate_whose_limbs_go_on() {
    use tubeloc_pipeline::pose_verifier::{PoseVerifier, Verdict};
    let (cam, image, ground, det) = one_tube_scene();
    let settings = PoseVerifier::refinement_settings();
    let refiner = tubeloc_refine::Refiner::new(&settings.tube, settings.refine.clone()).unwrap();
    let evidence = tubeloc_pipeline::shipped::pose_evidence("shipped").unwrap();
    let verdict = |image: &DynamicImage, max: Option<f64>| {
        let v = PoseVerifier { evidence: evidence.clone(), threshold: 0.0, threshold_grey: 0.0, nms_iou: 0.5, max_limb_continuation: max, fitted_on: String::new() };
        let frame = tubeloc_pipeline::Frame { image, camera: &cam, image_id: 1, ground: Some(ground), stereo: None };
        let out = v.verify(&refiner, &settings, &frame, std::slice::from_ref(&det), true).unwrap();
        assert_eq!(out.len(), 1);
        (out[0].verdict, out[0].pose.clone())
    };
    let (kept, pose) = verdict(&image, Some(0.6));
    assert_eq!(kept, Verdict::Kept);
    let rim = with_rim_band(&image, &cam, &pose);
    assert_eq!(verdict(&rim, Some(0.6)).0, Verdict::LimbsContinue);
    assert_eq!(verdict(&rim, None).0, Verdict::Kept);
}
