//! `tubeloc eval`: COCO evaluation (pycocotools-identical), with per-attribute breakdowns; with
//! `--poses`, evaluation of refined tube poses against exact poses ([`poses`]).

use anyhow::Context;
use std::path::PathBuf;
use tubeloc_core::coco::load_results;
use tubeloc_core::files::{write_atomic, write_json};
use tubeloc_core::CocoDataset;
use tubeloc_eval::breakdown::{self, Breakdown};
use tubeloc_eval::coco_eval::{CocoEvaluator, IouType};

mod poses;

/// Arguments of `tubeloc eval`.
#[derive(clap::Args)]
pub struct EvalArgs {
    /// Ground truth: a COCO dataset JSON file.
    #[arg(long)]
    gt: PathBuf,
    /// Detections: COCO results JSON files; several files (shards) are concatenated in order.
    #[arg(long, required_unless_present = "poses", num_args = 1..)]
    dt: Vec<PathBuf>,
    /// Pose evaluation instead: refined poses (JSON arrays of TubeAxisPose, `tubeloc refine
    /// --out`), each `LABEL=PATH` or `PATH` (label: the file stem); overlaid in the histograms.
    #[arg(long, num_args = 1..)]
    poses: Vec<String>,
    /// Pose evaluation: least visible fraction (annotations' `visible_fraction`) of the
    /// ground-truth tubes evaluated.
    #[arg(long, default_value_t = 0.5, value_parser = crate::args::unit_interval)]
    min_visible: f64,
    /// Pose evaluation of a stereo dataset: keep only the truths whose axis lies at least half
    /// inside the right image (`images[].right_camera`, `images[].T_left_right`; 21 points along
    /// the axis), the tubes that both cameras see. Tubes outside the right view get mono poses
    /// from a stereo refinement (no stereo points).
    #[arg(long)]
    in_both_views: bool,
    /// Pose evaluation: gate of the greedy matching on the centre distance, millimetres.
    #[arg(long, default_value_t = 50.0, value_parser = crate::args::positive_f64)]
    match_mm: f64,
    /// Pose evaluation: the annotation field holding the true pose: `T_cam_tube` (the exact
    /// pose of a rendered dataset) or `T_cam_tube_tags` (the tag-pair ground truth written by
    /// `tubeloc calib groundtruth`, the paper's protocol).
    #[arg(long, default_value = "T_cam_tube")]
    truth_field: String,
    /// IoU type: segm (mask IoU) or bbox (box IoU).
    #[arg(long, default_value = "segm")]
    iou_type: IouType,
    /// Output folder for metrics.json (and breakdown.json / breakdown.md with --by).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Break the metrics down by an image attribute (terrain, time, split...) or an annotation
    /// attribute (occlusion, dust...); repeatable.
    #[arg(long = "by", num_args = 1..)]
    by: Vec<String>,
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
    spinner.finish_and_clear();

    crate::out::out!("{}", result.summary_text());
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
        let report = report_of(&args, &result, &breakdowns);
        let md = tubeloc_eval::report::write_eval_report(out, &report).with_context(|| format!("writing the report in {}", out.display()))?;
        eprintln!("report: {}", md.display());
    }
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
            .map(|b| tubeloc_eval::report::Breakdown {
                attribute: b.attribute.clone(),
                metrics: vec!["AP50".into(), "AP".into(), "AR100".into()],
                rows: b.rows.iter().map(|r| (r.value.clone(), r.num_images, pick(&r.result))).collect(),
            })
            .collect(),
        poses: Vec::new(),
    }
}
