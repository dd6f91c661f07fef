//! `tubeloc eval`: COCO evaluation (pycocotools-identical), with per-attribute breakdowns; with
//! `--poses`, evaluation of refined tube poses against exact poses ([`poses`]).

use anyhow::Context;
use std::path::{Path, PathBuf};
use tubeloc_core::coco::load_results;
use tubeloc_core::files::{write_atomic, write_json};
use tubeloc_core::CocoDataset;
use tubeloc_eval::breakdown::{self, Breakdown};
use tubeloc_eval::coco_eval::{CocoEvaluator, IouType};

pub(crate) mod poses;

/// Default `--min-visible`.
const DEFAULT_MIN_VISIBLE: f64 = 0.5;
/// Default `--match-mm`.
const DEFAULT_MATCH_MM: f64 = 50.0;
/// Default `--target-precision`.
const DEFAULT_TARGET_PRECISION: f64 = 0.95;

/// Arguments of `tubeloc eval`.
#[derive(clap::Args)]
pub struct EvalArgs {
    /// Ground truth: a COCO dataset JSON file.
    #[arg(long)]
    pub(crate) gt: PathBuf,
    /// Detections: COCO results JSON files; several files (shards) are concatenated in order.
    #[arg(long, required_unless_present = "poses", num_args = 1..)]
    pub(crate) dt: Vec<PathBuf>,
    /// Pose evaluation instead: refined poses (JSON arrays of TubeAxisPose, `tubeloc refine
    /// --out`), each `LABEL=PATH` or `PATH` (label: the file stem); overlaid in the histograms.
    #[arg(long, num_args = 1.., value_parser = poses::label_and_path)]
    pub(crate) poses: Vec<(String, PathBuf)>,
    /// Pose evaluation: least visible fraction (annotations' `visible_fraction`) of the
    /// ground-truth tubes evaluated.
    #[arg(long, default_value_t = DEFAULT_MIN_VISIBLE, value_parser = crate::args::unit_interval)]
    pub(crate) min_visible: f64,
    /// Pose evaluation of a stereo dataset: keep only the truths whose axis lies at least half
    /// inside the right image (`images[].right_camera`, `images[].T_left_right`; 21 points along
    /// the axis), the tubes that both cameras see. Tubes outside the right view get mono poses
    /// from a stereo refinement (no stereo points).
    #[arg(long)]
    pub(crate) in_both_views: bool,
    /// Pose evaluation: gate of the greedy matching on the centre distance, millimetres.
    #[arg(long, default_value_t = DEFAULT_MATCH_MM, value_parser = crate::args::positive_f64)]
    pub(crate) match_mm: f64,
    /// Pose evaluation: the annotation field holding the true pose: `T_cam_tube` (the exact
    /// pose of a rendered dataset) or `T_cam_tube_tags` (the tag-pair ground truth written by
    /// `tubeloc calib groundtruth`, the paper's protocol).
    #[arg(long, default_value = "T_cam_tube")]
    pub(crate) truth_field: String,
    /// IoU type: segm (mask IoU) or bbox (box IoU).
    #[arg(long, default_value = "segm")]
    pub(crate) iou_type: IouType,
    /// Output folder for metrics.json (and breakdown.json / breakdown.md with --by).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Fit the probability that a detection is a tube from its score (Platt scaling on the
    /// detections' outcomes at IoU 0.5) and write it, with the threshold for
    /// `--target-precision`, to this JSON file (for `locate --calibration`).
    #[arg(long, value_name = "OUT.json")]
    pub(crate) calibrate: Option<PathBuf>,
    /// Precision the `--calibrate` threshold is chosen for.
    #[arg(long, default_value_t = DEFAULT_TARGET_PRECISION)]
    pub(crate) target_precision: f64,
    /// With --calibrate: the threshold also keeps at most this many false detections per
    /// image of the ground truth (the lowest threshold meeting both bounds).
    #[arg(long, requires = "calibrate", value_parser = crate::args::non_negative_f64)]
    pub(crate) max_false_per_image: Option<f64>,
    /// With --calibrate: the threshold also keeps at most this many false detections per
    /// image of the ground truth without any tube, counting the detections on those images
    /// only (the analogue of real frames without tubes; needs such images). With
    /// --fit-pose-verifier: the bound its cuts are chosen for (default 0.5, half the Line2D
    /// target of one per frame).
    #[arg(long, value_parser = crate::args::non_negative_f64)]
    pub(crate) max_false_per_negative_image: Option<f64>,
    /// Check a fitted calibration on these (held-out) detections: reliability diagram,
    /// expected calibration error, precision and recall at its threshold.
    #[arg(long, value_name = "CAL.json", conflicts_with = "calibrate")]
    pub(crate) calibration: Option<PathBuf>,
    /// Fit the probability that a refined pose is a tube from its detector score and its
    /// fit's evidence (`tubeloc_core::PoseEvidence`: logistic regression on the score, the share
    /// of contour samples on an edge, their number, the seal-end confidence and the axis's σ;
    /// labels: each --dt mask at IoU >= 0.5 with a true tube) and write it to this JSON file
    /// (for `tubeloc refine --pose-evidence`). Needs --evidence-poses.
    #[arg(long, value_name = "OUT.json", requires = "evidence_poses", conflicts_with_all = ["calibrate", "calibration"])]
    pub(crate) fit_pose_evidence: Option<PathBuf>,
    /// With --fit-pose-evidence: the refined poses of the --dt detections, one per detection in
    /// their order (`tubeloc refine --out`, written beside `--snapped-out`).
    #[arg(long, value_name = "POSES.json", requires = "fit_pose_evidence")]
    pub(crate) evidence_poses: Option<PathBuf>,
    /// Choose the cuts of a pose verifier (`tubeloc detect --method line2d --pose-verifier`)
    /// and write it, with the evidence of --verifier-evidence, to this JSON file: per image
    /// kind, the cut at which the --gt images without a tube (kind from their `grey` field)
    /// keep at most --max-false-per-negative-image --dt detections per image under each of
    /// their geometries (`geometry` field: `pds`, `assumed`), after suppression at mask IoU
    /// 0.5 (halfway between the last kept and the first dropped; the kind's highest). --dt: the snapped candidates scored by that evidence
    /// (`tubeloc refine --snapped-out S --pose-evidence E`).
    #[arg(long, value_name = "OUT.json", requires = "verifier_evidence", conflicts_with_all = ["calibrate", "calibration", "fit_pose_evidence"])]
    pub(crate) fit_pose_verifier: Option<PathBuf>,
    /// With --fit-pose-verifier: the pose evidence the --dt scores come from (`tubeloc eval
    /// --fit-pose-evidence`).
    #[arg(long, value_name = "EVIDENCE.json", requires = "fit_pose_verifier")]
    pub(crate) verifier_evidence: Option<PathBuf>,
    /// Free text stored in the `--calibrate` (or `--fit-pose-evidence`, `--fit-pose-verifier`)
    /// file's `fitted_on`.
    #[arg(long, default_value = "")]
    pub(crate) fitted_on: String,
    /// Break the metrics down by an image attribute (terrain, time, split...) or an annotation
    /// attribute (occlusion, dust...); repeatable.
    #[arg(long = "by", num_args = 1..)]
    pub(crate) by: Vec<String>,
    /// Give AP50 and AR with 95 % intervals from a bootstrap that resamples the values of this
    /// image attribute (e.g. `sol`: frames of one sol are not independent; 2000 resamples, seed
    /// 0); written to intervals.json with --out.
    #[arg(long, value_name = "ATTRIBUTE")]
    pub(crate) interval_by: Option<String>,
}

impl EvalArgs {
    /// COCO evaluation of the detections in `dt` against `gt`, written to `out`, broken down
    /// by the attributes `by` (what `tubeloc eval --gt G --dt D --out O --by ...` does).
    pub(crate) fn detections(gt: &Path, dt: &Path, out: &Path, by: &[&str]) -> Self {
        EvalArgs { dt: vec![dt.to_path_buf()], by: by.iter().map(|b| b.to_string()).collect(), ..EvalArgs::common(gt, out) }
    }

    /// Pose evaluation of the labelled poses files against `gt` (field `T_cam_tube`), written
    /// to `out` (what `tubeloc eval --gt G --poses L=P ... --out O` does).
    pub(crate) fn poses(gt: &Path, poses: &[(&str, &Path)], out: &Path) -> Self {
        EvalArgs { poses: poses.iter().map(|(l, p)| (l.to_string(), p.to_path_buf())).collect(), ..EvalArgs::common(gt, out) }
    }

    /// The command line's defaults with `gt` and `out`.
    fn common(gt: &Path, out: &Path) -> Self {
        EvalArgs {
            gt: gt.to_path_buf(),
            dt: Vec::new(),
            poses: Vec::new(),
            min_visible: DEFAULT_MIN_VISIBLE,
            in_both_views: false,
            match_mm: DEFAULT_MATCH_MM,
            truth_field: "T_cam_tube".into(),
            iou_type: IouType::Segm,
            out: Some(out.to_path_buf()),
            calibrate: None,
            target_precision: DEFAULT_TARGET_PRECISION,
            calibration: None,
            max_false_per_image: None,
            max_false_per_negative_image: None,
            fit_pose_evidence: None,
            evidence_poses: None,
            fit_pose_verifier: None,
            verifier_evidence: None,
            fitted_on: String::new(),
            by: Vec::new(),
            interval_by: None,
        }
    }
}

/// Runs the evaluation, prints the summary (and breakdown table), writes the JSON files.
pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    if !args.poses.is_empty() {
        return poses::run(&args.gt, &args.poses, &poses::TruthFilter { field: &args.truth_field, min_visible: args.min_visible, in_both_views: args.in_both_views }, args.match_mm, args.out.as_deref());
    }
    let gt = CocoDataset::load(&args.gt).with_context(|| format!("loading ground truth {}", args.gt.display()))?;
    let mut dt = Vec::new();
    for path in &args.dt {
        let r = load_results(path, &gt).with_context(|| format!("loading results {}", path.display()))?;
        dt.extend(r);
    }
    let spinner = indicatif::ProgressBar::new_spinner();
    spinner.set_message(format!("evaluating {} detections on {} images", dt.len(), gt.images.len()));
    spinner.enable_steady_tick(std::time::Duration::from_millis(120));
    let evaluator = CocoEvaluator::new(&gt, &dt, args.iou_type).context("preparing the evaluation")?;
    let result = evaluator.evaluate();
    let mut breakdowns: Vec<Breakdown> = Vec::new();
    for attr in &args.by {
        spinner.set_message(format!("breakdown by {attr}"));
        breakdowns.push(breakdown::breakdown(&evaluator, &gt, attr).with_context(|| format!("breakdown by {attr}"))?);
    }
    let intervals = match &args.interval_by {
        Some(attr) => {
            spinner.set_message(format!("intervals by {attr}"));
            let spec = tubeloc_eval::bootstrap::BootstrapSpec::default();
            Some(breakdown::intervals_by_image_attribute(&evaluator, &gt, attr, &spec).with_context(|| format!("--interval-by {attr}: {}", args.gt.display()))?)
        }
        None => None,
    };
    spinner.finish_and_clear();
    if args.max_false_per_negative_image.is_some() && args.calibrate.is_none() && args.fit_pose_verifier.is_none() {
        return Err(crate::args::usage("--max-false-per-negative-image needs --calibrate or --fit-pose-verifier"));
    }
    if !(args.target_precision > 0.0 && args.target_precision <= 1.0) {
        anyhow::bail!("--target-precision {} must be in (0, 1]", args.target_precision);
    }
    // Each detection's (image, score, is a tube at IoU 0.5), for the calibration and its
    // report, and the images holding a tube (the others are tube-free frames).
    let (outcomes50, with_tubes) =
        if args.calibrate.is_some() || args.calibration.is_some() { (evaluator.outcomes_at_iou50(), gt.annotations.iter().filter(|a| a.iscrowd == 0).map(|a| a.image_id).collect::<std::collections::HashSet<u64>>()) } else { Default::default() };
    let negatives = gt.images.iter().filter(|i| !with_tubes.contains(&i.id)).count();
    let calibration = match (&args.calibrate, &args.calibration) {
        (Some(_), _) => {
            let outcomes: Vec<(f64, bool)> = outcomes50.iter().map(|&(_, s, y)| (s, y)).collect();
            let (a, b) = tubeloc_eval::calibration::fit_platt(&outcomes);
            let mut c = tubeloc_core::ScoreCalibration {
                a,
                b,
                threshold: 1.0,
                target_precision: args.target_precision,
                fitted_on: args.fitted_on.clone(),
                max_false_per_image: args.max_false_per_image,
                max_false_per_negative_image: args.max_false_per_negative_image,
            };
            let probs: Vec<(f64, bool)> = outcomes.iter().map(|&(s, y)| (c.probability(s), y)).collect();
            let bound = args.max_false_per_image.map(|f| (f, gt.images.len()));
            c.threshold = tubeloc_eval::calibration::choose_threshold_bounded(&probs, args.target_precision, bound);
            if let Some(f) = args.max_false_per_negative_image {
                if negatives == 0 {
                    anyhow::bail!("--max-false-per-negative-image: {} has no image without a tube", args.gt.display());
                }
                let counted: Vec<bool> = outcomes50.iter().map(|o| !with_tubes.contains(&o.0)).collect();
                let t = tubeloc_eval::calibration::choose_threshold_counted(&probs, Some(&counted), args.target_precision, Some((f, negatives)));
                c.threshold = c.threshold.max(t);
            }
            Some(c)
        }
        (None, Some(p)) => {
            let c: tubeloc_core::ScoreCalibration = tubeloc_core::files::read_json(p).with_context(|| format!("reading calibration {}", p.display()))?;
            c.validate().map_err(|e| anyhow::anyhow!("calibration {}: {e}", p.display()))?;
            Some(c)
        }
        (None, None) => None,
    };
    let calibration_report = calibration.as_ref().map(|c| {
        let outcomes = &outcomes50;
        let probs: Vec<(f64, bool)> = outcomes.iter().map(|&(_, s, y)| (c.probability(s), y)).collect();
        let (bins, ece) = tubeloc_eval::calibration::reliability(&probs, 10);
        let kept: Vec<&(f64, bool)> = probs.iter().filter(|p| p.0 >= c.threshold).collect();
        let tp = kept.iter().filter(|p| p.1).count();
        let gt_n = gt.annotations.iter().filter(|a| a.iscrowd == 0).count();
        let precision = if kept.is_empty() { f64::NAN } else { tp as f64 / kept.len() as f64 };
        let recall = if gt_n == 0 { f64::NAN } else { tp as f64 / gt_n as f64 };
        let fp_per_image = (kept.len() - tp) as f64 / gt.images.len().max(1) as f64;
        // On the images without a tube (every detection there is false).
        let fp_negative = outcomes.iter().zip(&probs).filter(|(o, p)| !with_tubes.contains(&o.0) && p.0 >= c.threshold).count();
        let fp_per_negative = (negatives > 0).then(|| fp_negative as f64 / negatives as f64);
        eprintln!("calibration a {:.4} b {:.4} threshold {:.4}: ECE {ece:.4}; kept {} of {} detections, precision {precision:.4}, recall {recall:.4}, false positives per image {fp_per_image:.4}{}", c.a, c.b, c.threshold, kept.len(), probs.len(), fp_per_negative.map_or(String::new(), |f| format!(", per image without a tube {f:.4} ({negatives} images)")));
        serde_json::json!({"calibration": c, "ece": ece, "bins": bins, "kept": kept.len(), "detections": probs.len(), "precision_at_threshold": precision, "recall_at_threshold": recall, "false_positives_per_image": fp_per_image, "false_positives_per_negative_image": fp_per_negative})
    });
    if let (Some(out), Some(poses)) = (&args.fit_pose_evidence, &args.evidence_poses) {
        fit_pose_evidence(&args, &gt, &dt, poses, out, result.stats[1])?;
    }
    if let (Some(out), Some(evidence)) = (&args.fit_pose_verifier, &args.verifier_evidence) {
        fit_pose_verifier(&args, &gt, &dt, evidence, out)?;
    }
    if let (Some(c), Some(p)) = (&calibration, &args.calibrate) {
        write_json(p, c).with_context(|| format!("writing {}", p.display()))?;
        eprintln!("calibration -> {}", p.display());
    }

    crate::out::out!("{}", result.summary_text());
    if let (Some(i), Some(attr)) = (&intervals, &args.interval_by) {
        crate::out::outln!(
            "AP50 {:.3} [{:.3}, {:.3}], AR {:.3} [{:.3}, {:.3}]: 95 % intervals from a bootstrap over the {} values of {attr} (2000 resamples, seed 0)",
            i.ap50.estimate,
            i.ap50.lo,
            i.ap50.hi,
            i.ar.estimate,
            i.ar.lo,
            i.ar.hi,
            i.ap50.groups
        );
    }
    let table = breakdown::markdown_table(&breakdowns);
    if !breakdowns.is_empty() {
        crate::out::outln!("\n{table}");
    }
    if let Some(out) = &args.out {
        let mut metrics = result.to_json();
        metrics["gt"] = serde_json::json!(args.gt);
        metrics["dt"] = serde_json::json!(args.dt);
        let p = out.join("metrics.json");
        write_json(&p, &metrics).with_context(|| format!("writing {}", p.display()))?;
        if !breakdowns.is_empty() {
            let p = out.join("breakdown.json");
            write_json(&p, &breakdown::to_json(&breakdowns)).with_context(|| format!("writing {}", p.display()))?;
            let p = out.join("breakdown.md");
            write_atomic(&p, table.as_bytes()).with_context(|| format!("writing {}", p.display()))?;
        }
        if let (Some(i), Some(attr)) = (&intervals, &args.interval_by) {
            let p = out.join("intervals.json");
            write_json(&p, &serde_json::json!({"by": attr, "bootstrap": tubeloc_eval::bootstrap::BootstrapSpec::default(), "ap50": i.ap50, "ar": i.ar})).with_context(|| format!("writing {}", p.display()))?;
        }
        if let Some(cr) = &calibration_report {
            let p = out.join("calibration.json");
            write_json(&p, cr).with_context(|| format!("writing {}", p.display()))?;
        }
        let report = report_of(&args, &result, &breakdowns);
        let md = tubeloc_eval::report::write_eval_report(out, &report).with_context(|| format!("writing the report in {}", out.display()))?;
        eprintln!("report: {}", md.display());
    }
    Ok(())
}

/// `--fit-pose-evidence`: fits the pose-evidence model to the detections `dt` (labelled against
/// `gt`) and their refined poses (the file `poses`, in the same order), writes it to `out` and
/// prints its weights and the AP50 of the detections ranked by it (`ap50`: by their scores).
fn fit_pose_evidence(args: &EvalArgs, gt: &CocoDataset, dt: &[tubeloc_core::CocoResult], poses: &Path, out: &Path, ap50: f64) -> anyhow::Result<()> {
    let dt_files = args.dt.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ");
    let poses_list: Vec<tubeloc_core::TubeAxisPose> = tubeloc_core::files::read_json(poses).with_context(|| format!("reading poses {}", poses.display()))?;
    if poses_list.len() != dt.len() {
        anyhow::bail!("--evidence-poses {} holds {} poses but the detections ({dt_files}) are {}: the poses must be those of the detections, in their order (`tubeloc refine --out` with `--snapped-out`)", poses.display(), poses_list.len(), dt.len());
    }
    if let Some(k) = (0..dt.len()).find(|&k| dt[k].image_id != poses_list[k].image_id) {
        anyhow::bail!("--evidence-poses {}: pose {k} is on image {} but detection {k} ({dt_files}) on image {}: the poses must be those of the detections, in their order", poses.display(), poses_list[k].image_id, dt[k].image_id);
    }
    let labels = tubeloc_eval::pose_evidence_fit::tube_labels(gt, dt).map_err(|e| anyhow::anyhow!("labelling the detections {dt_files}: {e}"))?;
    let samples: Vec<_> = poses_list.iter().zip(&labels).map(|(p, &y)| (tubeloc_core::PoseEvidence::features(p), y)).collect();
    let model = tubeloc_eval::pose_evidence_fit::fit_pose_evidence(&samples, &args.fitted_on).map_err(|e| anyhow::anyhow!("fitting the pose evidence on {dt_files}: {e}"))?;
    let rescored = tubeloc_eval::pose_evidence_fit::scored_by_evidence(dt, &poses_list, &model);
    let ap50_evidence = CocoEvaluator::new(gt, &rescored, args.iou_type).context("evaluating the re-ranked detections")?.evaluate().stats[1];
    let weights: Vec<String> = model.features.iter().zip(model.weights).map(|(n, w)| format!("{n} {w:+.3}")).collect();
    eprintln!("pose evidence fitted on {} detections ({} tubes): {}, bias {:+.3}; AP50 on them {ap50:.3} ranked by score, {ap50_evidence:.3} by the pose evidence", dt.len(), labels.iter().filter(|&&y| y).count(), weights.join(", "), model.bias);
    write_json(out, &model).with_context(|| format!("writing {}", out.display()))?;
    eprintln!("pose evidence -> {}", out.display());
    Ok(())
}

/// The markdown report's content: the 12 numbers, the PR curves (area all, 100 detections) and
/// each breakdown as AP50 / AP / AR100 per value.
fn report_of(args: &EvalArgs, result: &tubeloc_eval::coco_eval::EvalResult, breakdowns: &[Breakdown]) -> tubeloc_eval::report::EvalReport {
    use tubeloc_eval::coco_eval::STATS;
    let pick = |r: &tubeloc_eval::coco_eval::EvalResult| vec![r.stats[1], r.stats[0], r.stats[8]];
    tubeloc_eval::report::EvalReport {
        title: "COCO evaluation".into(),
        inputs: std::iter::once(("ground truth".to_string(), args.gt.display().to_string()))
            .chain(args.dt.iter().map(|d| ("results".to_string(), d.display().to_string())))
            .chain(std::iter::once(("IoU type".to_string(), result.iou_type.name().to_string())))
            .collect(),
        stats: STATS.iter().zip(result.stats).map(|(s, v)| (s.name.to_string(), v)).collect(),
        pr_curves: result.iou_thrs.iter().enumerate().map(|(t, &thr)| (thr, result.pr_curve(t))).collect(),
        breakdowns: breakdowns
            .iter()
            .map(|b| tubeloc_eval::report::Breakdown { attribute: b.attribute.clone(), metrics: vec!["AP50".into(), "AP".into(), "AR100".into()], rows: b.rows.iter().map(|r| (r.value.clone(), r.num_images, pick(&r.result))).collect() })
            .collect(),
        poses: Vec::new(),
    }
}

/// `--fit-pose-verifier`: the cuts per image kind on the tube-free images of `gt` for the
/// candidates `dt` scored by the evidence file `evidence`
/// ([`tubeloc_eval::negative_cuts::kind_cuts`]); writes the pose verifier to `out`.
fn fit_pose_verifier(args: &EvalArgs, gt: &CocoDataset, dt: &[tubeloc_core::CocoResult], evidence: &Path, out: &Path) -> anyhow::Result<()> {
    use tubeloc_pipeline::pose_verifier::PoseVerifier;
    let model = tubeloc_pipeline::shipped::pose_evidence(&evidence.display().to_string()).map_err(|e| anyhow::anyhow!("--verifier-evidence: {e}"))?;
    let bound = args.max_false_per_negative_image.unwrap_or(0.5);
    const NMS_IOU: f64 = 0.5;
    let cuts = tubeloc_eval::negative_cuts::kind_cuts(gt, dt, NMS_IOU, bound).map_err(|e| anyhow::anyhow!("{}: {e}", args.gt.display()))?;
    for kind in [false, true] {
        if !cuts.groups.iter().any(|g| g.grey == kind) {
            eprintln!("warning: {} has no {} image without a tube: that kind gets the cut 0", args.gt.display(), if kind { "grey" } else { "colour" });
        }
    }
    let verifier = PoseVerifier { evidence: model, threshold: cuts.colour, threshold_grey: cuts.grey, nms_iou: NMS_IOU, max_limb_continuation: None, fitted_on: args.fitted_on.clone() };
    verifier.validate().map_err(|e| anyhow::anyhow!("the pose verifier: {e}"))?;
    write_json(out, &verifier).with_context(|| format!("writing {}", out.display()))?;
    for g in &cuts.groups {
        eprintln!("{} images, {} geometry: {} without a tube, {} detections after suppression, cut {:.4}", if g.grey { "grey" } else { "colour" }, if g.geometry.is_empty() { "unnamed" } else { &g.geometry }, g.images, g.detections, g.cut);
    }
    eprintln!("pose verifier cuts for at most {bound} false detections per tube-free image in each geometry: colour {:.4}, grey {:.4} -> {}", cuts.colour, cuts.grey, out.display());
    Ok(())
}
