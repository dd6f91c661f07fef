//! `tubeloc templates fit-verifier`: fits the Line2D clutter verifier
//! ([`tubeloc_detect::line2d::classify`]) on detections in training composites (rendered tubes
//! on real training frames; tube-free composites for more clutter) and chooses its default
//! threshold on validation composites.
//!
//! Each detection (the verifier keeps everything while fitting) is labelled a tube when its
//! mask overlaps a ground-truth tube mask with IoU >= 0.5. The threshold is the lowest
//! probability on a 0.01 grid at which the validation sets give at most `--max-fp-per-frame`
//! false detections per image; AP50 on the validation composites at each threshold is printed
//! beside it (COCO-style greedy matching in score order, 101-point interpolation).

use crate::cmd_detect_line2d::{detector_from_opts, Line2dOpts};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use serde_json::json;
use std::path::{Path, PathBuf};
use tubeloc_core::{files, CocoDataset, Rle};
use tubeloc_detect::line2d::classify::{Features, Verifier};

/// Arguments of `tubeloc templates fit-verifier`.
#[derive(clap::Args)]
pub struct FitArgs {
    /// Training composite sets (COCO folders from `tubeloc synth real --split train`, with or
    /// without tubes); repeatable. Never validation or test data.
    #[arg(long, required = true)]
    pub train: Vec<PathBuf>,
    /// Validation composite sets (`--split val`) on which the threshold is chosen; repeatable.
    #[arg(long, required = true)]
    pub val: Vec<PathBuf>,
    /// The threshold is the lowest at which the tube-free validation sets give at most this many
    /// false detections per image.
    #[arg(long, default_value_t = 0.5, value_parser = crate::args::non_negative_f64)]
    pub max_fp_per_frame: f64,
    /// Ridge weight on the standardized weights (the classes carry equal total weight,
    /// the number of samples).
    #[arg(long, default_value_t = 1.0, value_parser = crate::args::non_negative_f64)]
    pub l2: f64,
    /// Use at most this many images of each set, spread evenly over it (file order).
    #[arg(long)]
    pub max_images: Option<usize>,
    /// Folder caching each set's detections and features (`<name>.json`), reused when present.
    #[arg(long)]
    pub work: PathBuf,
    /// Output verifier JSON (e.g. detect/src/line2d/verifier.json).
    #[arg(long)]
    pub out: PathBuf,
    /// Line2D options (`--templates`, ...): the detector whose detections are verified.
    #[command(flatten)]
    pub line2d: Line2dOpts,
}

/// One detection of a set: its image, features and mask IoU with each ground-truth tube.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Sample {
    /// Image id.
    pub image_id: u64,
    /// Verifier features (None when not measurable: such detections get probability 0).
    pub features: Option<Features>,
    /// Mask IoU with each ground-truth annotation of the image, in annotation order.
    pub ious: Vec<f64>,
}

/// Detections of one set with the number of images and ground-truth tubes.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SetSamples {
    /// Set folder.
    pub set: String,
    /// Images.
    pub images: usize,
    /// Ground-truth tubes.
    pub tubes: usize,
    /// Detections.
    pub samples: Vec<Sample>,
}

/// Runs Line2D (verifier keeping everything) on a COCO set and labels each detection.
pub fn set_samples(opts: &Line2dOpts, set: &Path, max_images: Option<usize>) -> Result<SetSamples> {
    let mut o = opts.clone();
    o.min_probability = Some(0.0);
    o.no_verifier = false;
    let (mut det, camera) = detector_from_opts(&o)?;
    // Every detection of the first NMS, without the second suppression (which depends on the
    // probabilities being fitted).
    det.params.verified_overlap = f32::INFINITY;
    let gt = CocoDataset::load(&set.join("annotations.json")).with_context(|| format!("reading {}", set.join("annotations.json").display()))?;
    let mut images = crate::cmd_detect_learned::image_list(None, 0, Some(set))?;
    if let Some(n) = max_images.filter(|&n| n < images.len()) {
        let step = images.len() as f64 / n.max(1) as f64;
        images = (0..n).map(|i| images[(i as f64 * step) as usize].clone()).collect();
    }
    let cameras = crate::cmd_detect_learned::dataset_cameras(set)?;
    let bar = indicatif::ProgressBar::new(images.len() as u64);
    let mut samples = Vec::new();
    for (id, path) in &images {
        let im = gt.images.iter().find(|i| i.id == *id).context("image missing from annotations")?;
        let gts: Vec<Rle> = gt.annotations.iter().filter(|a| a.image_id == *id).filter_map(|a| a.segmentation.as_ref().map(|s| s.to_rle(im.height, im.width))).collect::<Result<_, _>>()?;
        let img = image::open(path).with_context(|| format!("reading {}", path.display()))?.to_rgb8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let dets = det.detect(img.as_raw(), w, h, cameras.get(id).or(camera.as_ref()))?;
        for d in dets {
            let ious = Rle::iou(std::slice::from_ref(&d.mask), &gts, &vec![false; gts.len()]);
            samples.push(Sample { image_id: *id, features: d.features, ious });
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let kept: std::collections::HashSet<u64> = images.iter().map(|i| i.0).collect();
    let tubes = gt.annotations.iter().filter(|a| kept.contains(&a.image_id)).count();
    Ok(SetSamples { set: set.display().to_string(), images: images.len(), tubes, samples })
}

fn cached(opts: &Line2dOpts, set: &Path, max_images: Option<usize>, work: &Path) -> Result<SetSamples> {
    let name: String = format!("{}_{}", set.display(), max_images.map_or("all".to_string(), |n| n.to_string())).chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    let path = work.join(format!("{name}.json"));
    if path.exists() {
        return files::read_json(&path).with_context(|| format!("reading {}", path.display()));
    }
    let s = set_samples(opts, set, max_images)?;
    files::write_json(&path, &s)?;
    Ok(s)
}

/// AP50 (COCO-style: greedy matching in decreasing probability, 101-point interpolated
/// precision) and false detections per image of the detections with probability >= `thr`.
pub fn ap50_and_fp(sets: &[SetSamples], probs: &[Vec<f32>], thr: f32) -> (f64, f64) {
    let (mut tubes, mut images, mut fp_total) = (0usize, 0usize, 0usize);
    let mut outcomes: Vec<(f32, bool)> = Vec::new();
    for (s, p) in sets.iter().zip(probs) {
        tubes += s.tubes;
        images += s.images;
        let mut order: Vec<usize> = (0..s.samples.len()).filter(|&i| p[i] >= thr).collect();
        order.sort_by(|&a, &b| p[b].total_cmp(&p[a]));
        let mut taken: std::collections::HashSet<(u64, usize)> = Default::default();
        for i in order {
            let d = &s.samples[i];
            let best = d.ious.iter().enumerate().filter(|(k, &iou)| iou >= 0.5 && !taken.contains(&(d.image_id, *k))).max_by(|a, b| a.1.total_cmp(b.1)).map(|(k, _)| k);
            if let Some(k) = best {
                taken.insert((d.image_id, k));
            } else {
                fp_total += 1;
            }
            outcomes.push((p[i], best.is_some()));
        }
    }
    outcomes.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut tp, mut prec, mut rec) = (0usize, Vec::new(), Vec::new());
    for (k, o) in outcomes.iter().enumerate() {
        tp += o.1 as usize;
        prec.push(tp as f64 / (k + 1) as f64);
        rec.push(tp as f64 / tubes.max(1) as f64);
    }
    for k in (0..prec.len().saturating_sub(1)).rev() {
        prec[k] = prec[k].max(prec[k + 1]);
    }
    let ap = (0..=100).map(|r| r as f64 / 100.0).map(|r| rec.iter().position(|&x| x >= r).map_or(0.0, |k| prec[k])).sum::<f64>() / 101.0;
    (if tubes == 0 { f64::NAN } else { ap }, fp_total as f64 / images.max(1) as f64)
}

/// Runs `tubeloc templates fit-verifier`.
pub fn run(a: FitArgs) -> Result<()> {
    std::fs::create_dir_all(&a.work)?;
    let train: Vec<SetSamples> = a.train.iter().map(|s| cached(&a.line2d, s, a.max_images, &a.work)).collect::<Result<_>>()?;
    let data: Vec<(Features, bool)> = train.iter().flat_map(|s| s.samples.iter()).filter_map(|d| d.features.map(|f| (f, d.ious.iter().any(|&i| i >= 0.5)))).collect();
    let n_pos = data.iter().filter(|d| d.1).count();
    eprintln!("training: {} detections ({} tubes, {} clutter) in {} images", data.len(), n_pos, data.len() - n_pos, train.iter().map(|s| s.images).sum::<usize>());
    let mut v = Verifier::fit(&data, a.l2).map_err(|e| anyhow::anyhow!("fitting the verifier: {e}"))?;
    let val: Vec<SetSamples> = a.val.iter().map(|s| cached(&a.line2d, s, a.max_images, &a.work)).collect::<Result<_>>()?;
    let probs: Vec<Vec<f32>> = val.iter().map(|s| s.samples.iter().map(|d| d.features.as_ref().map_or(0.0, |f| v.probability(f))).collect()).collect();
    let composites: Vec<usize> = (0..val.len()).filter(|&i| val[i].tubes > 0).collect();
    let (vc, pc): (Vec<SetSamples>, Vec<Vec<f32>>) = composites.iter().map(|&i| (val[i].clone(), probs[i].clone())).unzip();
    let mut table = Vec::new();
    let mut chosen = None;
    eprintln!("threshold  val AP50  val FP/image");
    // False detections are counted on the tube-free validation sets (the analogue of real
    // frames without tubes), or on all of them when there is none.
    let free: Vec<usize> = (0..val.len()).filter(|&i| val[i].tubes == 0).collect();
    let free = if free.is_empty() { (0..val.len()).collect() } else { free };
    let (vf, pf): (Vec<SetSamples>, Vec<Vec<f32>>) = free.iter().map(|&i| (val[i].clone(), probs[i].clone())).unzip();
    for k in 0..1000 {
        let thr = k as f32 / 1000.0;
        let (_, fp) = ap50_and_fp(&vf, &pf, thr);
        let (ap, _) = ap50_and_fp(&vc, &pc, thr);
        if k % 50 == 0 {
            eprintln!("{thr:9.2}  {ap:8.3}  {fp:12.3}");
        }
        table.push(json!({"threshold": thr, "ap50": ap, "fp_per_image": fp}));
        if chosen.is_none() && fp <= a.max_fp_per_frame {
            chosen = Some((thr, ap, fp));
        }
    }
    let Some((thr, ap, fp)) = chosen else { bail!("no threshold below 1 gives at most {} false detections per validation image", a.max_fp_per_frame) };
    v.threshold = thr;
    let args: Vec<String> = std::env::args().collect();
    v.provenance = json!({
        "command": args.join(" "),
        "train": train.iter().map(|s| json!({"set": s.set, "images": s.images, "tubes": s.tubes, "detections": s.samples.len()})).collect::<Vec<_>>(),
        "training_detections": {"tubes": n_pos, "clutter": data.len() - n_pos},
        "val": val.iter().map(|s| json!({"set": s.set, "images": s.images, "tubes": s.tubes, "detections": s.samples.len()})).collect::<Vec<_>>(),
        "rule": format!("lowest threshold on a 0.001 grid with at most {} false detections per tube-free validation image", a.max_fp_per_frame),
        "val_at_threshold": {"ap50": ap, "fp_per_image": fp},
        "l2": a.l2,
    });
    files::write_json(&a.work.join("threshold_table.json"), &table)?;
    files::write_json(&a.out, &v)?;
    eprintln!("threshold {thr:.2}: val AP50 {ap:.3}, {fp:.3} false detections per image -> {}", a.out.display());
    Ok(())
}
