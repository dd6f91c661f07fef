//! The real stage of `tubeloc bench`: detectors and `locate` on real rover frames.
//!
//! (a) Composites on the real **test** frames (split by sol, `tubeloc synth real`): grey
//!     frames with their PDS camera models (ground and sun of the frame; tubes shaded in
//!     600-800 nm, record 0086), and colour Mastcam
//!     frames under the view `--assumed-view auto` takes for them (M-100 frames `m100`, the
//!     others the documented mast view, [`AssumedView::of_frame`]); learned
//!     detection at the working scale, COCO AP50 / AR, and the reliability of the calibrated
//!     probability on these held-out detections. Besides, the part's grey backgrounds under
//!     the assumed Navcam view (what a grey frame without a camera model gets), for both
//!     detectors.
//! (b) False positives per frame on `negatives_val` (detections kept, and tubes that `locate`
//!     at its defaults hands the planner) (real frames without tubes, never used for
//!     training or choosing settings): learned detections kept at the calibration's
//!     threshold, under an assumed camera per frame kind (grey Navcam: 45 degree field of view,
//!     1.9 m high, 30 degrees down; colour: the mast view).
//! (c) Line2D on the same composites and negatives: the default template library built once
//!     into `<out>/real/line2d/templates.tlt`, every frame resampled to its pixel scale, the
//!     candidates verified by their poses on each frame's ground; AP50 / AR, false detections
//!     per frame, time; and the fused detector (the learned and the verified Line2D detections
//!     by their pose evidence, [`tubeloc_pipeline::FusedTubeDetector`]) on the same frames.
//! Results go to `report.md` and `summary.json` in `<out>/real` (`<out>/real_val` for the
//! validation part). A kind of frame (grey with PDS cameras, colour Mastcam) or `negatives_val`
//! that the data folder lacks is left out: its entries in `summary.json` are `null`, and the
//! report says what is missing.

use crate::cmd_detect_line2d::Line2dRunner;
use anyhow::{bail, Context, Result};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use tubeloc_core::{files, CocoDataset, ScoreCalibration};
use tubeloc_detect::learned::DecodeConfig;
use tubeloc_eval::coco_eval::{CocoEvaluator, IouType};
use tubeloc_pipeline::FusedTubeDetector;

/// Options of the real stage.
pub struct RealStage {
    /// The real data folder (`../shared/data/real_mars`).
    pub data: PathBuf,
    /// Learned model.
    pub model: crate::cmd_detect_learned::ModelChoice,
    /// Score calibration (probability and threshold).
    pub calibration: ScoreCalibration,
    /// The part of the real data the composites and the PDS frames come from: `Test` (the
    /// figures to report) or `Val` (the figures to choose settings on; `negatives_val`, kept for
    /// measuring false positives, is then not run).
    pub split: tubeloc_synth::real_frames::RealSplit,
    /// Keep at most this many frames per set (small runs, e.g. in CI).
    pub frames: Option<usize>,
    /// Composites per grey test frame (at least; see `min_tubes`).
    pub per_grey_frame: u32,
    /// Tubes each composite set holds at least: where a set made with its composites per frame
    /// holds fewer, it is made again with as many more composites per frame as that shortfall
    /// asks (`None`: as made).
    pub min_tubes: Option<usize>,
    /// `locate` and its grasp checks on at most this many composites of each set (all when `None`).
    pub grasp_images: Option<usize>,
    /// Line2D far-search factors (colour, grey) (`tubeloc detect --far-scale`).
    pub line2d_far_scale: (f64, f64),
    /// Line2D largest enlargement to the library's scale (`tubeloc detect --max-upsample`).
    pub line2d_max_upsample: f64,
}

/// Writes a detector's results on a composite set (ground truth `gt`) to
/// `<out>/detections.json` and reads them back as COCO results, as `tubeloc eval` would.
fn saved_results(gt: &CocoDataset, out: &Path, dets: &impl serde::Serialize) -> Result<Vec<tubeloc_core::coco::CocoResult>> {
    let path = out.join("detections.json");
    files::write_json(&path, dets)?;
    Ok(tubeloc_core::coco::load_results(&path, gt)?)
}

/// The most composites per frame [`composite_set`] makes to reach its tubes.
const MAX_PER_VIEW: u32 = 32;

/// The composite set of one kind of frame (`tubeloc synth real --kind KIND`) in `out`, or
/// `None` where the data holds no frame of that kind in the part (a folder of grey frames only,
/// or one without `with_cameras/cameras.json`): that kind's rows are then left out. Grey frames
/// are taken under `grey_view` (`tubeloc synth real --grey-view`). With
/// `min_tubes`, a set of fewer tubes is made again with more composites per frame, the fewest
/// that the tubes per composite so far say reach it (at most [`MAX_PER_VIEW`]).
#[allow(clippy::too_many_arguments)]
fn composite_set(
    data: &Path,
    split: tubeloc_synth::real_frames::RealSplit,
    kind: crate::cmd_synth_real::RealKind,
    grey_view: crate::cmd_synth_real::GreyViewArg,
    per_view: u32,
    min_tubes: Option<usize>,
    min_size: u32,
    frames: Option<usize>,
    seed: u64,
    out: &Path,
) -> Result<Option<PathBuf>> {
    use crate::cmd_synth_real::RealKind;
    if out.join("annotations.json").exists() {
        return Ok(Some(out.to_path_buf()));
    }
    if kind == RealKind::Grey && grey_view == crate::cmd_synth_real::GreyViewArg::Pds && !data.join("with_cameras").join("cameras.json").exists() {
        return Ok(None);
    }
    // `tubeloc synth real` as the real stage runs it: composites of one to four tubes at
    // 1.5-5 m on each frame of the kind in the part, no appearance randomization.
    let mut args = crate::cmd_synth_real::RealArgs {
        data: data.to_path_buf(),
        split,
        kind,
        per_view: per_view.max(1),
        tubes: (1, 4),
        range_m: (1.5, 5.0),
        grey_view,
        hfov_deg: tubeloc_synth::real_frames::TRAINING_HFOV_DEG,
        min_size,
        randomize: Some(false),
        colour_as_grey: false,
        limit: frames,
        seed,
        force: true,
        out: out.to_path_buf(),
    };
    let views = crate::cmd_synth_real::frames(&args)?;
    if views.is_empty() {
        return Ok(None);
    }
    loop {
        let (_, tubes) = crate::cmd_synth_real::write_set(&args, &views)?;
        let Some(want) = min_tubes.filter(|&want| tubes < want) else { break };
        if args.per_view >= MAX_PER_VIEW {
            eprintln!("warning: {}: {tubes} tubes, fewer than the {want} asked for, at {MAX_PER_VIEW} composites per frame on {} frames", out.display(), views.len());
            break;
        }
        // The tubes per composite per frame so far, scaled to the shortfall; one more at least.
        let needed = (args.per_view as f64 * want as f64 / tubes.max(1) as f64).ceil() as u32;
        args.per_view = needed.max(args.per_view + 1).min(MAX_PER_VIEW);
    }
    Ok(Some(out.to_path_buf()))
}

/// `f` on a kind's composite set, or `null` where the data has no such set.
fn each(set: &Option<PathBuf>, f: impl FnOnce(&Path) -> Result<Value>) -> Result<Value> {
    set.as_deref().map_or(Ok(Value::Null), f)
}

/// Detects with the learned model at each image's working scale and evaluates: returns the
/// summary numbers.
fn detect_eval(set: &Path, model: &crate::cmd_detect_learned::ModelChoice, cal: &ScoreCalibration, out: &Path) -> Result<Value> {
    std::fs::create_dir_all(out)?;
    let data = crate::detect_dataset::DetectionDataset::load(set)?;
    let images = data.images();
    let scales = data.working_scales(&images, Some(tubeloc_detect::scale::RangeBand::default()));
    let t = Instant::now();
    let dets = crate::cmd_detect_learned::run_learned(model, &images, &scales, &DecodeConfig::default())?;
    let ms = t.elapsed().as_secs_f64() * 1e3 / images.len().max(1) as f64;
    let gt = data.coco();
    let dt = saved_results(gt, out, &dets)?;
    let ev = CocoEvaluator::new(gt, &dt, IouType::Segm)?;
    let r = ev.evaluate();
    let n_gt = gt.annotations.len();
    let mut v = json!({"images": gt.images.len(), "tubes": n_gt, "ap50": r.stats[1], "ap": r.stats[0], "ar": r.stats[8], "ms_per_image": ms, "found_by_width": crate::bench_widths::found_by_width(gt, &dt)?});
    merge(&mut v, at_threshold(&ev, cal, n_gt));
    merge(&mut v, crate::bench_intervals::ap_ar_by_sol(gt, &ev));
    v["by_sol"] = crate::bench_sols::by_sol(gt, &ev)?;
    Ok(v)
}

/// The reliability of `cal`'s probability (ECE, bins of 0.1) and the precision / recall at its
/// threshold on the matches at IoU 0.5 of `ev` (`n_gt` tubes).
fn at_threshold(ev: &CocoEvaluator, cal: &ScoreCalibration, n_gt: usize) -> Value {
    let probs: Vec<(f64, bool)> = ev.outcomes_at_iou50().iter().map(|&(_, s, y)| (cal.probability(s), y)).collect();
    let (bins, ece) = tubeloc_eval::calibration::reliability(&probs, 10);
    let kept: Vec<_> = probs.iter().filter(|p| p.0 >= cal.threshold).collect();
    let tp = kept.iter().filter(|p| p.1).count();
    json!({"ece": ece, "reliability": bins, "kept": kept.len(), "precision_at_threshold": if kept.is_empty() { f64::NAN } else { tp as f64 / kept.len() as f64 }, "recall_at_threshold": tp as f64 / n_gt.max(1) as f64})
}

/// Adds the fields of the object `extra` to the object `v`.
fn merge(v: &mut Value, extra: Value) {
    if let (Some(o), Value::Object(e)) = (v.as_object_mut(), extra) {
        o.extend(e);
    }
}

/// Mono refinement of a set's learned detections on each image's own ground (`--ground
/// auto`: the composites' `T_world_cam` has the ground at z = 0) and pose errors against the
/// composite truth; returns the `mono` summaries (axis degrees, across-axis millimetres) and
/// the segm AP50 / AR of the detections with their masks snapped to the poses' silhouettes
/// (`refine --snapped-out`, default settings).
fn poses(set: &Path, dir: &Path) -> Result<Value> {
    use crate::cmd_refine::dataset::{refine_dataset, DatasetJob, DatasetSeeds};
    let (dets, poses, seeds, snapped) = (dir.join("detections.json"), dir.join("poses.json"), dir.join("seeds.json"), dir.join("snapped.json"));
    let t = Instant::now();
    let mut job = DatasetJob::new(set.to_path_buf(), DatasetSeeds::Detections(dets), poses.clone());
    job.ground = Some(crate::cmd_refine::GroundArg::Auto);
    job.seeds_out = Some(seeds.clone());
    job.snapped_out = Some(snapped.clone());
    refine_dataset(&job)?;
    let refine_ms = t.elapsed().as_secs_f64() * 1e3;
    let snapped_dets: Value = files::read_json(&snapped)?;
    let gt = CocoDataset::load(&set.join("annotations.json"))?;
    let dt = saved_results(&gt, &dir.join("snapped_eval"), &snapped_dets)?;
    let snapped_ev = CocoEvaluator::new(&gt, &dt, IouType::Segm)?;
    let snapped_eval = snapped_ev.evaluate();
    // The same snapped detections ranked by the shipped pose evidence (what `tubeloc refine
    // --snapped-out --pose-evidence shipped` writes).
    let evidence = tubeloc_pipeline::shipped::pose_evidence("shipped")?;
    let pose_list: Vec<tubeloc_core::TubeAxisPose> = files::read_json(&poses)?;
    anyhow::ensure!(pose_list.len() == dt.len(), "{} poses for {} snapped detections", pose_list.len(), dt.len());
    let ranked = tubeloc_eval::pose_evidence_fit::scored_by_evidence(&dt, &pose_list, &evidence);
    let ranked_ev = CocoEvaluator::new(&gt, &ranked, IouType::Segm)?;
    let ranked_eval = ranked_ev.evaluate();
    // Its calibration on these held-out composites: the label it was fitted with (the snapped
    // mask at IoU >= 0.5 with a true tube).
    let labels = tubeloc_eval::pose_evidence_fit::tube_labels(&gt, &ranked).map_err(anyhow::Error::msg)?;
    let probs: Vec<(f64, bool)> = ranked.iter().zip(labels).map(|(d, y)| (d.score, y)).collect();
    let (_, evidence_ece) = tubeloc_eval::calibration::reliability(&probs, 10);
    let filter = crate::cmd_eval::poses::TruthFilter { field: "T_cam_tube", min_visible: 0.5, in_both_views: false };
    let labels = [("coarse".to_string(), seeds.clone()), ("mono".to_string(), poses.clone())];
    crate::cmd_eval::poses::run(&set.join("annotations.json"), &labels, &filter, 50.0, Some(&dir.join("pose_eval")))?;
    let m: Value = files::read_json(&dir.join("pose_eval").join("pose_metrics.json"))?;
    let mono = m["poses"].as_array().and_then(|v| v.iter().find(|p| p["label"] == "mono")).cloned().unwrap_or(Value::Null);
    let pairs: Value = files::read_json(&dir.join("pose_eval").join("pose_eval.json"))?;
    let mono_pairs = pairs.as_array().and_then(|v| v.iter().find(|p| p["label"] == "mono")).map(|p| p["evaluation"]["pairs"].clone()).unwrap_or(Value::Null);
    let median_ci = |field: &str| crate::bench_intervals::median_by_sol(&gt, &mono_pairs, field);
    let mut snapped_fig =
        json!({"ap50": snapped_eval.stats[1], "ap": snapped_eval.stats[0], "ar": snapped_eval.stats[8], "refine_ms_per_image": refine_ms / gt.images.len().max(1) as f64, "found_by_width": crate::bench_widths::found_by_width(&gt, &dt)?});
    merge(&mut snapped_fig, crate::bench_intervals::ap_ar_by_sol(&gt, &snapped_ev));
    let mut ranked_fig = json!({"ap50": ranked_eval.stats[1], "ap": ranked_eval.stats[0], "ar": ranked_eval.stats[8], "ece": evidence_ece});
    merge(&mut ranked_fig, crate::bench_intervals::ap_ar_by_sol(&gt, &ranked_ev));
    Ok(json!({
        "truths": mono["n_truths"], "matched": mono["n_matched"],
        "axis_deg_median": mono["summaries"]["axis_angle_deg"]["median"], "axis_deg_p90": mono["summaries"]["axis_angle_deg"]["p90"],
        "across_mm_median": mono["summaries"]["perpendicular_mm"]["median"], "across_mm_p90": mono["summaries"]["perpendicular_mm"]["p90"],
        "along_mm_median": mono["summaries"]["along_axis_abs_mm"]["median"], "along_mm_p90": mono["summaries"]["along_axis_abs_mm"]["p90"],
        "axis_deg_median_ci": median_ci("axis_angle_deg"), "across_mm_median_ci": median_ci("perpendicular_mm"), "along_mm_median_ci": median_ci("along_axis_abs_mm"),
        "snapped": snapped_fig,
        "snapped_pose_evidence": ranked_fig,
    }))
}

/// The Line2D library of the real stage: the default library (`tubeloc templates build` at its
/// defaults: the paper's camera at half resolution, 1-4 m), built once into
/// `<out>/real/line2d/templates.tlt`; every real frame is resampled to its pixel scale.
fn line2d_library(dir: &Path) -> Result<PathBuf> {
    let lib = dir.join("line2d").join("templates.tlt");
    if !lib.exists() {
        std::fs::create_dir_all(lib.parent().unwrap_or(dir))?;
        let camera = tubeloc_detect::line2d::LibraryParams::default_camera();
        crate::cmd_templates::build_for_camera(&camera, tubeloc_detect::line2d::ViewParams::default(), &lib)?;
    }
    Ok(lib)
}

/// Line2D options at their defaults (shipped verifier and threshold) with library `lib` and
/// the stage's far search and enlargement limit.
fn line2d_opts(lib: &Path, stage: &RealStage) -> crate::cmd_detect_line2d::Line2dOpts {
    let mut opts = crate::cmd_detect::line2d_defaults();
    opts.templates = Some(lib.to_path_buf());
    (opts.far_scale, opts.max_upsample) = (stage.line2d_far_scale, stage.line2d_max_upsample);
    opts
}

/// Line2D verified by pose on a composite set (each image's own camera, resampled to the
/// library's scale), and with `fused` (its calibration and folder) the fused detections made
/// from the same Line2D matches (record 0069): for each, COCO segm AP50 / AR, false detections
/// per image, time per image (the fused row's: Line2D's and its own). `[line2d, fused]`, the
/// second `Null` without `fused`.
fn line2d_eval(set: &Path, det: &FusedTubeDetector, fused: Option<(&ScoreCalibration, &Path)>, out: &Path) -> Result<[Value; 2]> {
    let data = crate::detect_dataset::DetectionDataset::load(set)?;
    let (images, cameras, grounds) = (data.images(), data.cameras(), data.grounds());
    let (mut l2_dets, mut fused_dets) = (Vec::new(), Vec::new());
    let (mut l2_ms, mut fused_ms) = (0.0, 0.0);
    for (id, path) in &images {
        let img = image::DynamicImage::ImageRgb8(tubeloc_detect::input::open_eight_bit(path).with_context(|| format!("reading {}", path.display()))?.into_rgb8());
        let (camera, ground) = (cameras.get(id), grounds.get(id));
        let t = Instant::now();
        let (found, _) = det.line2d_verified(&img, camera, ground, *id)?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        l2_ms += ms;
        l2_dets.extend(found.iter().map(|d| d.to_coco_json(*id)));
        if fused.is_some() {
            let t = Instant::now();
            // Line2D's time counts where its matches are reused; under another camera than
            // Line2D's row (an image without one of its size), the fused detector matches again.
            let (both, reused_ms) = match crate::cmd_detect_line2d::fused_camera(det, &img, camera) {
                (c, true) => (det.fuse(&img, &c, ground, *id, found)?, ms),
                (c, false) => (det.detect_fused(&img, &c, ground, *id)?, 0.0),
            };
            fused_ms += reused_ms + t.elapsed().as_secs_f64() * 1e3;
            fused_dets.extend(crate::cmd_detect_line2d::fused_json(both, *id));
        }
    }
    let gt = data.coco();
    let n = images.len().max(1) as f64;
    let l2 = scored(gt, &l2_dets, l2_ms / n, None, out)?;
    let fused = match fused {
        Some((cal, dir)) => scored(gt, &fused_dets, fused_ms / n, Some(cal), dir)?,
        None => Value::Null,
    };
    Ok([l2, fused])
}

/// Saves detections `dets` (COCO results entries) of the composite set `gt` in `out` and scores
/// them: COCO segm AP50 / AR with their intervals by sol, by sol, by tube width, false
/// detections per image, `ms` per image, and with `cal` the precision / recall at its threshold.
fn scored(gt: &CocoDataset, dets: &[Value], ms: f64, cal: Option<&ScoreCalibration>, out: &Path) -> Result<Value> {
    std::fs::create_dir_all(out)?;
    let dt = saved_results(gt, out, &dets)?;
    let ev = CocoEvaluator::new(gt, &dt, IouType::Segm)?;
    let r = ev.evaluate();
    let fp = ev.outcomes_at_iou50().iter().filter(|o| !o.2).count();
    let n = gt.images.len().max(1) as f64;
    let mut v = json!({"images": gt.images.len(), "tubes": gt.annotations.len(), "detections": dets.len(), "ap50": r.stats[1], "ap": r.stats[0], "ar": r.stats[8], "false_per_image": fp as f64 / n, "ms_per_image": ms, "found_by_width": crate::bench_widths::found_by_width(gt, &dt)?});
    merge(&mut v, crate::bench_intervals::ap_ar_by_sol(gt, &ev));
    v["by_sol"] = crate::bench_sols::by_sol(gt, &ev)?;
    if let Some(cal) = cal {
        merge(&mut v, at_threshold(&ev, cal, gt.annotations.len()));
    }
    Ok(v)
}

/// The folder of the real stage of `split` under the bench's output folder `out`:
/// `<out>/real` for the test part, `<out>/real_val` for the validation part, so that a run of
/// one part never stands in for the other.
pub fn stage_dir(out: &Path, split: tubeloc_synth::real_frames::RealSplit) -> PathBuf {
    match split {
        tubeloc_synth::real_frames::RealSplit::Test => out.join("real"),
        other => out.join(format!("real_{}", other.name())),
    }
}

/// Runs the real stage into [`stage_dir`]; returns the report's markdown section.
pub fn run(stage: &RealStage, out: &Path) -> Result<String> {
    if !stage.data.join("MANIFEST.tsv").exists() {
        bail!("{}: no MANIFEST.tsv (the real data folder, ../shared/data/real_mars)", stage.data.display());
    }
    let dir = stage_dir(out, stage.split);
    std::fs::create_dir_all(&dir)?;
    let part = stage.split.name();
    // negatives_val measures false positives only: never run where settings are chosen.
    let negatives_dir = stage.data.join("negatives_val");
    let measures = matches!(stage.split, tubeloc_synth::real_frames::RealSplit::Test | tubeloc_synth::real_frames::RealSplit::All);
    let with_negatives = measures && negatives_dir.is_dir();
    use crate::cmd_synth_real::GreyViewArg;
    let grey_set = composite_set(&stage.data, stage.split, crate::cmd_synth_real::RealKind::Grey, GreyViewArg::Pds, stage.per_grey_frame, stage.min_tubes, 500, stage.frames, 22, &dir.join(format!("{part}_grey")))?;
    // The part's grey backgrounds of at least 500 px under the assumed Navcam view (45 degree
    // field, 1.9 m high, 30 degrees down): what `locate --assumed-view navcam` makes of a grey
    // frame without a camera model, and a view down onto nearer ground than the validation
    // sols' camera-model frames show (record 0088).
    let grey_assumed_set = composite_set(&stage.data, stage.split, crate::cmd_synth_real::RealKind::Grey, GreyViewArg::Assumed, stage.per_grey_frame, stage.min_tubes, 500, stage.frames, 24, &dir.join(format!("{part}_grey_assumed")))?;
    let colour_set = composite_set(&stage.data, stage.split, crate::cmd_synth_real::RealKind::Colour, GreyViewArg::Pds, 1, stage.min_tubes, 300, stage.frames, 23, &dir.join(format!("{part}_colour")))?;
    if grey_set.is_none() && colour_set.is_none() {
        bail!("{}: no frames of the {part} part to composite on: no grey frame with a PDS camera model (with_cameras/cameras.json) and no colour Mastcam background of its sols", stage.data.display());
    }
    let grey = each(&grey_set, |s| detect_eval(s, &stage.model, &stage.calibration, &dir.join("learned_grey")))?;
    let colour = each(&colour_set, |s| detect_eval(s, &stage.model, &stage.calibration, &dir.join("learned_colour")))?;
    let grey_assumed = each(&grey_assumed_set, |s| detect_eval(s, &stage.model, &stage.calibration, &dir.join("learned_grey_assumed")))?;
    let grey_poses = each(&grey_set, |s| poses(s, &dir.join("learned_grey")))?;
    let colour_poses = each(&colour_set, |s| poses(s, &dir.join("learned_colour")))?;
    let learned_detector: Arc<dyn tubeloc_pipeline::TubeDetector> = Arc::new(stage.model.detector()?);
    // `locate`'s settings at its defaults: the stage's score calibration, the model's pose
    // evidence (`tubeloc_pipeline::shipped::locate_settings`, without loading the calibration again).
    let mut learned_settings = tubeloc_pipeline::LocatorSettings::default();
    learned_settings.calibration = stage.calibration.clone();
    learned_settings.pose_evidence = tubeloc_pipeline::shipped::locator_pose_evidence("learned", stage.model.path())?;
    let neg = if with_negatives { crate::bench_negatives::negatives(&stage.data, &learned_detector, &learned_settings, stage.frames)? } else { Value::Null };
    let neg_pds = crate::bench_negatives::pds_negatives(&stage.data, stage.split, &stage.model, &learned_settings, stage.frames)?;
    // `locate` (mono, each frame's own ground) on the composites: its grasp checks, and how many
    // of the tubes it hands over are composited tubes.
    let grasp = each(&grey_set, |s| crate::bench_grasp::run(s, &dir.join("learned_grey").join("detections.json"), false, stage.grasp_images, Some(&learned_settings)))?;
    let grasp_colour = each(&colour_set, |s| crate::bench_grasp::run(s, &dir.join("learned_colour").join("detections.json"), false, stage.grasp_images, Some(&learned_settings)))?;
    // Line2D: the default library, every frame resampled to its scale, shipped verifier.
    let lib = line2d_library(&dir)?;
    let l2_opts = line2d_opts(&lib, stage);
    // Line2D verified by pose, and fused: the learned detections and the verified Line2D ones
    // by their pose evidence (record 0069), from one runner, so that each image's Line2D
    // matches are made once. Libraries and models are loaded outside the timings.
    let fusion = crate::cmd_detect_line2d::Fusion { model: stage.model.load()?, decode: DecodeConfig::default(), range: Some(tubeloc_detect::scale::RangeBand::default()), origin: stage.model.name() };
    let runner = Line2dRunner::new(crate::cmd_detect_line2d::detector_from_opts(&l2_opts)?.0, Some(fusion), l2_opts.pose_verifier()?, tubeloc_pipeline::pose_verifier::CLUTTER_FLOOR)?;
    let fused = runner.fused().context("the fused runner")?;
    let fused_cal = tubeloc_pipeline::shipped::fused_calibration(stage.model.path())?;
    let none = || [Value::Null, Value::Null];
    let [l2_grey, fused_grey] = grey_set.as_deref().map_or(Ok(none()), |s| line2d_eval(s, fused, Some((&fused_cal, &dir.join("fused_grey"))), &dir.join("line2d_grey")))?;
    let [l2_colour, fused_colour] = colour_set.as_deref().map_or(Ok(none()), |s| line2d_eval(s, fused, Some((&fused_cal, &dir.join("fused_colour"))), &dir.join("line2d_colour")))?;
    let [l2_grey_assumed, _] = grey_assumed_set.as_deref().map_or(Ok(none()), |s| line2d_eval(s, fused, None, &dir.join("line2d_grey_assumed")))?;
    let [l2_neg, fused_neg] = if with_negatives { crate::bench_negatives::line2d_negatives(&stage.data, fused, stage.frames)? } else { none() };
    drop(runner);
    // `locate --detector fused` at its defaults (its calibration's threshold) on the same frames.
    let fused_detector: Arc<dyn tubeloc_pipeline::TubeDetector> = Arc::new(tubeloc_pipeline::shipped::fused_detector(Some(&lib), stage.model.path(), "1:4")?);
    let mut fused_settings = tubeloc_pipeline::LocatorSettings::default();
    fused_settings.calibration = fused_cal.clone();
    let fused_located = if with_negatives { crate::bench_negatives::negatives(&stage.data, &fused_detector, &fused_settings, stage.frames)? } else { Value::Null };
    // `locate --detector fused` on the composites, as the learned detector's rows above.
    let fused_grasp = each(&grey_set, |s| crate::bench_grasp::run(s, &dir.join("fused_grey").join("detections.json"), false, stage.grasp_images, Some(&fused_settings)))?;
    let fused_grasp_colour = each(&colour_set, |s| crate::bench_grasp::run(s, &dir.join("fused_colour").join("detections.json"), false, stage.grasp_images, Some(&fused_settings)))?;
    let verifier = tubeloc_detect::line2d::Verifier::shipped();
    let (threshold, threshold_grey, threshold_far) = (verifier.threshold, verifier.threshold_for(true), verifier.threshold_for_search(true, true));
    let pose_verifier = tubeloc_pipeline::shipped::line2d_pose_verifier("shipped")?;
    let summary = json!({"split": part, "model": stage.model.name(), "calibration": stage.calibration, "learned": {"grey": grey, "colour": colour, "grey_assumed": grey_assumed}, "poses_grey": grey_poses, "poses_colour": colour_poses, "negatives": neg, "negatives_pds": neg_pds, "grasp_grey": grasp, "grasp_colour": grasp_colour,
        "line2d": {"library": lib.display().to_string(), "verifier_threshold": threshold, "verifier_threshold_grey": threshold_grey, "verifier_threshold_far": threshold_far, "pose_verifier": {"threshold": pose_verifier.threshold, "threshold_grey": pose_verifier.threshold_grey, "nms_iou": pose_verifier.nms_iou}, "far_scale": [stage.line2d_far_scale.0, stage.line2d_far_scale.1], "max_upsample": stage.line2d_max_upsample, "grey": l2_grey, "colour": l2_colour, "grey_assumed": l2_grey_assumed, "negatives": l2_neg},
        "fused": {"grasp_grey": fused_grasp, "grasp_colour": fused_grasp_colour, "calibration": fused_cal, "grey": fused_grey, "colour": fused_colour, "negatives": fused_neg, "locate_negatives": fused_located}});
    files::write_json(&dir.join("summary.json"), &summary)?;
    let mut md = String::new();
    let the_sols = if stage.split == tubeloc_synth::real_frames::RealSplit::All { "every sol".to_string() } else { format!("the {part} sols") };
    let title = match stage.split {
        tubeloc_synth::real_frames::RealSplit::Test => "## Real imagery (test part, split by sol)\n".to_string(),
        tubeloc_synth::real_frames::RealSplit::All => {
            format!("## Real imagery (every frame of `{}`, whatever its sol: a held-out measurement on frames the model was not trained on; on the shipped data it includes the training backgrounds)\n", stage.data.display())
        }
        _ => format!("## Real imagery ({part} part, split by sol: for choosing settings, not for reporting)\n"),
    };
    writeln!(md, "{title}").ok();
    writeln!(md, "Composites of rendered tubes on real rover frames of {the_sols} (`tubeloc synth real --split {part}`): grey frames with their PDS camera models (ground and sun of the frame; tubes shaded in the 600-800 nm band of these monochrome cameras, record 0086), colour Mastcam frames under the view `--assumed-view auto` takes for them (1.9 m high, 30 degrees down; a 6.8 degree field of view for the M-100 frames by their product names, 20 degrees for the M-34 frames and the panorama tiles). \"Assumed Navcam view\" rows: the grey backgrounds of {the_sols} (at least 500 px) under the view `--assumed-view navcam` takes for a grey frame without a camera model (45 degree field of view, 1.9 m high, 30 degrees down), a frame whose own camera model sees sky where that view puts tubes left out; the tubes nearer and wider than on the validation sols' camera-model frames, which look 17 degrees down or above the horizon (record 0088). Learned model `{}`, each image at its working scale.{}\n", stage.model.name(), stage.min_tubes.map_or(String::new(), |n| format!(" Each set is made to hold at least {n} tubes: with {} composites per grey frame and 1 per colour frame, and again with more per frame (up to {MAX_PER_VIEW}) where that gives fewer tubes.", stage.per_grey_frame))).ok();
    writeln!(
        md,
        "AP50 and AR carry their 95 % interval in brackets, from a bootstrap that resamples the sols (2000 resamples, seed 0: frames of one sol share terrain and light, so a sol is drawn whole); so do the figures per tube-free frame below.\n"
    )
    .ok();
    writeln!(md, "| set | images | tubes | AP50 | AR | ms / image | precision / recall at P >= {:.3} | ECE |", stage.calibration.threshold).ok();
    writeln!(md, "|---|---:|---:|---:|---:|---:|---|---:|").ok();
    // One row: the columns every detector has, then the learned one's precision / recall and
    // ECE, or Line2D's false detections per image.
    let num = |v: &Value, key: &str| v[key].as_f64().unwrap_or(f64::NAN);
    let row = |name: &str, v: &Value, rest: String| {
        use crate::bench_intervals::bracket;
        format!("| {name} | {} | {} | {:.3}{} | {:.3}{} | {:.0} | {rest} |", v["images"], v["tubes"], num(v, "ap50"), bracket(&v["ap50_ci"]), num(v, "ar"), bracket(&v["ar_ci"]), num(v, "ms_per_image"))
    };
    let present = |v: &&Value| !v.is_null();
    for (name, v) in [("grey (PDS geometry)", &grey), ("grey (assumed Navcam view)", &grey_assumed), ("colour (assumed view)", &colour)].into_iter().filter(|r| present(&r.1)) {
        writeln!(md, "{}", row(name, v, format!("{:.3} / {:.3} | {:.3}", num(v, "precision_at_threshold"), num(v, "recall_at_threshold"), num(v, "ece")))).ok();
    }
    // The same detections with their masks snapped to their mono-refined poses: the masks of a
    // learned detection followed by `tubeloc refine --snapped-out`.
    for (name, v, p) in [("grey, snapped to poses", &grey, &grey_poses), ("colour, snapped to poses", &colour, &colour_poses)].into_iter().filter(|r| present(&r.1)) {
        let s = &p["snapped"];
        let merged = json!({"images": v["images"], "tubes": v["tubes"], "ap50": s["ap50"], "ap50_ci": s["ap50_ci"], "ar": s["ar"], "ar_ci": s["ar_ci"], "ms_per_image": num(v, "ms_per_image") + num(s, "refine_ms_per_image")});
        writeln!(md, "{}", row(name, &merged, "- | -".into())).ok();
    }
    // The snapped detections ranked by the pose evidence (`refine --pose-evidence shipped`).
    for (name, v, p) in [("grey, snapped, ranked by pose evidence", &grey, &grey_poses), ("colour, snapped, ranked by pose evidence", &colour, &colour_poses)].into_iter().filter(|r| present(&r.1)) {
        let s = &p["snapped_pose_evidence"];
        let merged = json!({"images": v["images"], "tubes": v["tubes"], "ap50": s["ap50"], "ap50_ci": s["ap50_ci"], "ar": s["ar"], "ar_ci": s["ar_ci"], "ms_per_image": num(v, "ms_per_image") + num(&p["snapped"], "refine_ms_per_image")});
        writeln!(md, "{}", row(name, &merged, format!("- | {:.3}", num(s, "ece")))).ok();
    }
    for (name, v) in [("Line2D grey (PDS geometry)", &l2_grey), ("Line2D grey (assumed Navcam view)", &l2_grey_assumed), ("Line2D colour (assumed view)", &l2_colour)].into_iter().filter(|r| present(&r.1)) {
        writeln!(md, "{}", row(name, v, format!("{:.2} false / image | -", num(v, "false_per_image")))).ok();
    }
    for (name, v) in [("fused grey (PDS geometry)", &fused_grey), ("fused colour (assumed view)", &fused_colour)].into_iter().filter(|r| present(&r.1)) {
        let at = match v["kept"].as_u64() {
            Some(0) => "none kept".to_string(),
            _ => format!("{:.3} / {:.3}", num(v, "precision_at_threshold"), num(v, "recall_at_threshold")),
        };
        writeln!(md, "{}", row(name, v, format!("{:.2} false / image; at P >= {:.3}: {at} | {:.3}", num(v, "false_per_image"), fused_cal.threshold, num(v, "ece")))).ok();
    }
    let far_grey = stage.line2d_far_scale.1;
    writeln!(md, "\nLine2D rows: the default template library (paper camera at half resolution, 1-4 m), each frame resampled to its pixel scale (`f_library / f_image`), grey frames enlarged to it searched again {far_grey}x further enlarged (record 0055), matches whose scale disagrees with the frame's ground dropped (record 0054), every candidate the shipped clutter verifier scores refined in mono on the frame's ground, its mask snapped to the pose, and kept where the probability that its pose is a tube reaches the shipped pose verifier's cut ({:.3} on colour frames, {:.3} on grey ones; `tubeloc detect --method line2d`, record 0068); time: matching and verification. Their precision column gives the false detections per image instead.", pose_verifier.threshold, pose_verifier.threshold_grey).ok();
    writeln!(md, "\nFused rows (`tubeloc detect --method fused`, record 0069): the learned detections, each refined on the frame's ground, snapped and scored by the shipped model's pose evidence, and the Line2D detections verified by pose as in the Line2D rows, in one list, the less probable of two overlapping at mask IoU > 0.5 dropped; time: both detectors and the refinements. Their precision column gives the false detections per image, then the precision / recall at the fused calibration's threshold (what `locate --detector fused` hands over), and its ECE.").ok();
    let f = |v: &Value| v.as_f64().map(|x| format!("{x:.2}")).unwrap_or_else(|| "-".into());
    writeln!(md, "\n\"Snapped to poses\" rows: the learned detections refined in mono on each frame's own ground (`tubeloc refine --ground auto --snapped-out`, default settings), each mask replaced by its converged pose's silhouette within 8 px of it where they agree (record 0048); time: detection + refinement. \"Ranked by pose evidence\" rows: the same masks, each scored by the probability that its pose is a tube from the detector's score and the fit's evidence (`--pose-evidence shipped`, record 0066); their ECE is that probability's against the snapped mask at IoU >= 0.5 with a true tube.").ok();
    for (kind, _) in [("grey", &grey_set), ("colour", &colour_set)].into_iter().filter(|r| r.1.is_none()) {
        writeln!(md, "\nNo {kind} frames of {the_sols} in `{}`: the {kind} rows are left out.", stage.data.display()).ok();
    }
    if grey_assumed_set.is_none() {
        writeln!(md, "\nNo grey background of {the_sols} of at least 500 px in `{}`: the assumed Navcam view rows are left out.", stage.data.display()).ok();
    }
    let mut width_rows: Vec<(String, &Value)> = [("grey", &grey, &grey_poses, &l2_grey, &fused_grey), ("colour", &colour, &colour_poses, &l2_colour, &fused_colour)]
        .into_iter()
        .flat_map(|(kind, learned, poses, l2, fused)| {
            [(format!("learned {kind}"), &learned["found_by_width"]), (format!("learned {kind}, snapped"), &poses["snapped"]["found_by_width"]), (format!("Line2D {kind}"), &l2["found_by_width"]), (format!("fused {kind}"), &fused["found_by_width"])]
        })
        .collect();
    width_rows.extend([("learned grey, assumed Navcam view".to_string(), &grey_assumed["found_by_width"]), ("Line2D grey, assumed Navcam view".to_string(), &l2_grey_assumed["found_by_width"])]);
    if let Some(t) = crate::bench_widths::table(&width_rows) {
        writeln!(md, "\nTubes found, by their width in the image (`f D / r`: focal length, body diameter 17.1 mm, distance): a detection of the frame whose mask overlaps the tube's at IoU >= 0.5, whatever its score, i.e. what a perfect ranking of the detections would find (found / tubes):\n\n{}", t.trim_end()).ok();
    }
    if let Some(t) = crate::bench_sols::table(&[("learned AP50 / AR", &grey["by_sol"]), ("Line2D", &l2_grey["by_sol"]), ("fused", &fused_grey["by_sol"])]) {
        writeln!(md, "\nGrey composites (PDS geometry) by sol, each scored on its own frames (camera: the background's product name, `--assumed-view` names):\n\n{}", t.trim_end()).ok();
    }
    for (kind, p) in [("grey", &grey_poses), ("colour", &colour_poses)].into_iter().filter(|r| present(&r.1)) {
        use crate::bench_intervals::bracket;
        writeln!(md, "\nMono refinement of the learned detections on the {kind} {part} composites (each frame's own ground, `--ground auto`; tubes at least half visible, matched within 50 mm): {} of {} tubes, axis {}{} / {} deg, across the axis {}{} / {} mm, centre along the axis {}{} / {} mm (median [95 % interval by sol] / p90).", p["matched"], p["truths"], f(&p["axis_deg_median"]), bracket(&p["axis_deg_median_ci"]), f(&p["axis_deg_p90"]), f(&p["across_mm_median"]), bracket(&p["across_mm_median_ci"]), f(&p["across_mm_p90"]), f(&p["along_mm_median"]), bracket(&p["along_mm_median_ci"]), f(&p["along_mm_p90"])).ok();
    }
    if with_negatives {
        use crate::bench_intervals::by_sol_note;
        writeln!(md, "\nReal frames without tubes (`negatives_val`, {} frames): learned detections kept at the threshold **{:.3} per frame**{}, {:.2} per frame before it; `locate` at its defaults (assumed camera and ground: each frame's figure is what `tubeloc locate --assumed-view auto --image F` gives: the view of the mast camera its product name names, else navcam for a grey frame and mast for a colour one) hands the planner **{:.3} tubes per frame**{}.\n", neg["frames"], neg["kept_per_frame"].as_f64().unwrap_or(f64::NAN), by_sol_note(&neg["kept_per_frame_ci"]), neg["detections_per_frame"].as_f64().unwrap_or(f64::NAN), neg["located_per_frame"].as_f64().unwrap_or(f64::NAN), by_sol_note(&neg["located_per_frame_ci"])).ok();
        let l2_what = format!(
            "Line2D on the same frames (assumed cameras and ground, resampled to the library's scale, grey frames enlarged to it searched twice, verified by pose at {:.3} colour / {:.3} grey)",
            pose_verifier.threshold, pose_verifier.threshold_grey
        );
        for (what, v) in [(l2_what.as_str(), &l2_neg), ("Fused on the same frames", &fused_neg)] {
            writeln!(
                md,
                "{what}: **{:.3} false detections per frame**{}, at most {} on one frame, {:.0} ms per frame.\n",
                v["kept_per_frame"].as_f64().unwrap_or(f64::NAN),
                by_sol_note(&v["kept_per_frame_ci"]),
                v["max_per_frame"],
                v["ms_per_image"].as_f64().unwrap_or(f64::NAN)
            )
            .ok();
        }
        writeln!(
            md,
            "`locate --detector fused` at its defaults (assumed camera and ground, P >= {:.3}) hands the planner **{:.3} tubes per frame**{}.\n",
            fused_cal.threshold,
            fused_located["located_per_frame"].as_f64().unwrap_or(f64::NAN),
            by_sol_note(&fused_located["located_per_frame_ci"])
        )
        .ok();
        let columns = [("learned kept", &neg, "kept"), ("`locate`", &neg, "located"), ("Line2D", &l2_neg, "kept"), ("fused", &fused_neg, "kept"), ("`locate --detector fused`", &fused_located, "located")];
        writeln!(md, "By folder of `negatives_val` (camera and frame size; per frame):\n\n{}", crate::bench_negatives::folder_table(&columns)).ok();
    } else if measures {
        writeln!(md, "\nReal frames without tubes: no `negatives_val` folder in `{}`.\n", stage.data.display()).ok();
    } else {
        writeln!(md, "\nReal frames without tubes (`negatives_val`): not run on the {part} part; they measure false positives only.\n").ok();
    }
    if neg_pds["frames"].as_u64().unwrap_or(0) == 0 {
        writeln!(md, "Real frames of {the_sols} with PDS camera models (`with_cameras`, pinhole, at least 512 px): none in `{}`.\n", stage.data.display()).ok();
    } else {
        writeln!(md, "Real frames of {the_sols} with PDS camera models (`with_cameras`, {} pinhole frames of at least 512 px, none showing a tube), each under its own camera and ground (`tubeloc locate --rig with_cameras/cameras.json --image F`): `locate` at its defaults hands the planner **{:.3} tubes per frame**{}.\n", neg_pds["frames"], neg_pds["located_per_frame"].as_f64().unwrap_or(f64::NAN), crate::bench_intervals::by_sol_note(&neg_pds["located_per_frame_ci"])).ok();
    }
    writeln!(
        md,
        "`locate` at its defaults on the {part} composites (mono; learned detections, each frame's own ground, tubes at or above the probability threshold whose pose evidence reaches the floor, record 0078, and whose limbs end with them, record 0080; `--detector fused` rows: the fused detections at the fused calibration's threshold whose limbs end with them): the tubes it hands the planner, how many of them are composited tubes (centre within 50 mm of one, matched one to one), and its grasp collision checks (ground plane and other tubes):\n\n{}",
        crate::bench_grasp::table(&[("grey composites", &grasp), ("colour composites", &grasp_colour), ("grey composites, `--detector fused`", &fused_grasp), ("colour composites, `--detector fused`", &fused_grasp_colour)].into_iter().filter(|r| present(&r.1)).collect::<Vec<_>>())
    )
    .ok();
    for (kind, g) in [("grey", &grasp), ("colour", &grasp_colour), ("grey (`--detector fused`)", &fused_grasp), ("colour (`--detector fused`)", &fused_grasp_colour)] {
        let listed: Vec<String> = g["false_located"]
            .as_array()
            .into_iter()
            .flatten()
            .flat_map(|im| {
                im["false_tubes"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .map(move |t| format!("`{}` (P {:.3}, {:.2} m from the nearest true tube)", im["image"].as_str().unwrap_or("?"), t["probability"].as_f64().unwrap_or(f64::NAN), t["nearest_truth_m"].as_f64().unwrap_or(f64::NAN)))
            })
            .collect();
        if !listed.is_empty() {
            writeln!(md, "Located {kind} tubes that are no composited tube: {}.\n", listed.join("; ")).ok();
        }
    }
    let (kind, reliability) = if present(&&grey) { ("grey", &grey["reliability"]) } else { ("colour", &colour["reliability"]) };
    writeln!(md, "Reliability of the calibrated probability on the {kind} {part} detections (bins of 0.1: mean predicted / observed / count):\n").ok();
    if let Some(bins) = reliability.as_array() {
        for b in bins.iter().filter(|b| b["count"].as_u64().unwrap_or(0) > 0) {
            writeln!(md, "- [{:.1}, {:.1}): {:.3} / {:.3} / {}", b["lo"].as_f64().unwrap_or(0.0), b["hi"].as_f64().unwrap_or(0.0), b["mean_probability"].as_f64().unwrap_or(f64::NAN), b["frequency"].as_f64().unwrap_or(f64::NAN), b["count"]).ok();
        }
    }
    files::write_atomic(&dir.join("report.md"), md.as_bytes())?;
    Ok(md)
}
