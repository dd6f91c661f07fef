//! `tubeloc eval`: COCO evaluation (pycocotools-identical), with per-attribute breakdowns.

use anyhow::Context;
use std::path::PathBuf;
use tubeloc_core::coco::load_results;
use tubeloc_core::files::{write_atomic, write_json};
use tubeloc_core::CocoDataset;
use tubeloc_eval::breakdown::{self, Breakdown};
use tubeloc_eval::coco_eval::{CocoEvaluator, IouType};

/// Arguments of `tubeloc eval`.
#[derive(clap::Args)]
pub struct EvalArgs {
    /// Ground truth: a COCO dataset JSON file.
    #[arg(long)]
    gt: PathBuf,
    /// Detections: COCO results JSON files; several files (shards) are concatenated in order.
    #[arg(long, required = true, num_args = 1..)]
    dt: Vec<PathBuf>,
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

    print!("{}", result.summary_text());
    let table = breakdown::markdown_table(&breakdowns);
    if !breakdowns.is_empty() {
        println!("\n{table}");
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
    }
    Ok(())
}
