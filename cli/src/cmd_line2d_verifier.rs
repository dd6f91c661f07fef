//! `tubeloc templates fit-verifier`: fits the Line2D clutter verifier
//! ([`tubeloc_detect::line2d::classify`]) on detections in training composites (rendered tubes
//! on real training frames; tube-free composites for more clutter) and chooses its default
//! threshold on validation composites.
//!
//! Each detection (the verifier keeps everything while fitting) is labelled a tube when its
//! mask overlaps a ground-truth tube mask with IoU >= 0.5. The thresholds, one for colour
//! images and one for grey ones (three equal channels), are each the lowest probability on a
//! 0.001 grid at which the tube-free validation images of that kind give at most
//! `--max-fp-per-frame` false detections per image; AP50 on the validation composites at each
//! threshold is printed beside it (COCO-style greedy matching in score order, 101-point
//! interpolation).

use crate::cmd_detect_line2d::{detector_from_opts, Line2dOpts};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use serde_json::json;
use std::path::{Path, PathBuf};
use tubeloc_core::{files, Rle};
use tubeloc_detect::line2d::classify::{Features, Verifier};

/// Arguments of `tubeloc templates fit-verifier`.
#[derive(clap::Args)]
pub struct FitArgs {
    /// Training composite sets (COCO folders from `tubeloc synth real --split train`, with or
    /// without tubes); repeatable. Never validation or test data.
    #[arg(long, required_unless_present = "weights", conflicts_with = "weights")]
    pub train: Vec<PathBuf>,
    /// Keep the weights of this verifier JSON (e.g. the shipped one) and choose only its
    /// thresholds on `--val` (its training provenance is kept under `weights`).
    #[arg(long)]
    pub weights: Option<PathBuf>,
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
    /// Folder caching each set's detections and features (`<name>_<images>_<options hash>.json`),
    /// reused when present.
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
    /// Per image: id, ground-truth tubes, and whether it is grey (three equal channels).
    pub per_image: Vec<(u64, usize, bool)>,
    /// Detections.
    pub samples: Vec<Sample>,
}

impl SetSamples {
    /// The part of the set on grey (`true`) or colour images, with their probabilities.
    fn of_kind(&self, probs: &[f32], grey: bool) -> (SetSamples, Vec<f32>) {
        let ids: std::collections::HashSet<u64> = self.per_image.iter().filter(|i| i.2 == grey).map(|i| i.0).collect();
        let (samples, p): (Vec<Sample>, Vec<f32>) = self.samples.iter().zip(probs).filter(|(d, _)| ids.contains(&d.image_id)).map(|(d, &p)| (d.clone(), p)).unzip();
        let per_image: Vec<(u64, usize, bool)> = self.per_image.iter().filter(|i| i.2 == grey).copied().collect();
        (SetSamples { set: self.set.clone(), images: per_image.len(), tubes: per_image.iter().map(|i| i.1).sum(), per_image, samples }, p)
    }
}

/// Runs Line2D (verifier keeping everything; each image's ground, when the set gives one, for
/// the ground-consistency check) on a COCO set and labels each detection.
pub fn set_samples(opts: &Line2dOpts, set: &Path, max_images: Option<usize>) -> Result<SetSamples> {
    let mut o = opts.clone();
    o.min_probability = Some(0.0);
    o.no_verifier = false;
    let (mut det, camera) = detector_from_opts(&o)?;
    // Every detection of the first NMS, without the second suppression (which depends on the
    // probabilities being fitted).
    det.params.verified_overlap = f32::INFINITY;
    let data = crate::detect_dataset::DetectionDataset::load(set)?;
    let gt = data.coco();
    let mut images = data.images();
    if let Some(n) = max_images.filter(|&n| n < images.len()) {
        let step = images.len() as f64 / n.max(1) as f64;
        images = (0..n).map(|i| images[(i as f64 * step) as usize].clone()).collect();
    }
    let (cameras, grounds) = (data.cameras(), data.grounds());
    let bar = indicatif::ProgressBar::new(images.len() as u64);
    let mut samples = Vec::new();
    let mut per_image = Vec::new();
    for (id, path) in &images {
        let im = gt.images.iter().find(|i| i.id == *id).context("image missing from annotations")?;
        let gts: Vec<Rle> = gt.annotations.iter().filter(|a| a.image_id == *id).filter_map(|a| a.segmentation.as_ref().map(|s| s.to_rle(im.height, im.width))).collect::<Result<_, _>>()?;
        let img = tubeloc_detect::input::open_eight_bit(path).with_context(|| format!("reading {}", path.display()))?.into_rgb8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let dets = det.detect_on_ground(img.as_raw(), w, h, cameras.get(id).or(camera.as_ref()), grounds.get(id))?;
        per_image.push((*id, gts.len(), tubeloc_detect::input::is_grey_rgb8(img.as_raw())));
        for d in dets {
            let ious = Rle::iou(std::slice::from_ref(&d.mask), &gts, &vec![false; gts.len()]);
            samples.push(Sample { image_id: *id, features: d.features, ious });
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let tubes = per_image.iter().map(|i| i.1).sum();
    Ok(SetSamples { set: set.display().to_string(), images: images.len(), tubes, per_image, samples })
}

fn cached(opts: &Line2dOpts, set: &Path, max_images: Option<usize>, work: &Path) -> Result<SetSamples> {
    // Keyed by the set, the image subset and the Line2D options (a cache made with other
    // options is not reused).
    let key = {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        format!("{opts:?}").hash(&mut h);
        h.finish()
    };
    let name: String = format!("{}_{}_{key:016x}", set.display(), max_images.map_or("all".to_string(), |n| n.to_string())).chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    let path = work.join(format!("{name}.json"));
    if path.exists() {
        match files::read_json::<SetSamples>(&path) {
            Ok(s) => return Ok(s),
            // A cache of an older format: computed again.
            Err(e) => eprintln!("warning: {}: {e:#}; computing it again", path.display()),
        }
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

/// Sets of samples with the probability of each sample.
type SetsWithProbs = (Vec<SetSamples>, Vec<Vec<f32>>);

/// Runs `tubeloc templates fit-verifier`.
pub fn run(a: FitArgs) -> Result<()> {
    std::fs::create_dir_all(&a.work)?;
    let args: Vec<String> = std::env::args().collect();
    let (mut v, fitted) = match &a.weights {
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            let v = Verifier::from_json(&text).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?;
            let kept = json!({"file": p.display().to_string(), "provenance": v.provenance});
            (v, kept)
        }
        None => {
            let train: Vec<SetSamples> = a.train.iter().map(|s| cached(&a.line2d, s, a.max_images, &a.work)).collect::<Result<_>>()?;
            let data: Vec<(Features, bool)> = train.iter().flat_map(|s| s.samples.iter()).filter_map(|d| d.features.map(|f| (f, d.ious.iter().any(|&i| i >= 0.5)))).collect();
            let n_pos = data.iter().filter(|d| d.1).count();
            eprintln!("training: {} detections ({} tubes, {} clutter) in {} images", data.len(), n_pos, data.len() - n_pos, train.iter().map(|s| s.images).sum::<usize>());
            let v = Verifier::fit(&data, a.l2).map_err(|e| anyhow::anyhow!("fitting the verifier: {e}"))?;
            let fitted = json!({
                "command": args.join(" "),
                "train": train.iter().map(|s| json!({"set": s.set, "images": s.images, "tubes": s.tubes, "detections": s.samples.len()})).collect::<Vec<_>>(),
                "training_detections": {"tubes": n_pos, "clutter": data.len() - n_pos},
                "l2": a.l2,
            });
            (v, fitted)
        }
    };
    let val: Vec<SetSamples> = a.val.iter().map(|s| cached(&a.line2d, s, a.max_images, &a.work)).collect::<Result<_>>()?;
    let probs: Vec<Vec<f32>> = val.iter().map(|s| s.samples.iter().map(|d| d.features.as_ref().map_or(0.0, |f| v.probability(f))).collect()).collect();
    // Per image kind (colour, grey): the lowest threshold at which the tube-free validation
    // images of that kind give at most `max_fp_per_frame` false detections each (all
    // validation images of the kind when none is tube-free); AP50 on its composites beside it.
    let mut table = Vec::new();
    let mut chosen = [None, None];
    eprintln!("threshold  colour AP50  colour FP/image  grey AP50  grey FP/image");
    let kind_sets = |grey: bool, free: bool| -> SetsWithProbs { val.iter().zip(&probs).filter(|(s, _)| (s.tubes == 0) == free).map(|(s, p)| s.of_kind(p, grey)).filter(|(s, _)| s.images > 0).unzip() };
    let sets: Vec<[SetsWithProbs; 2]> = [false, true]
        .into_iter()
        .map(|grey| {
            let free = kind_sets(grey, true);
            let free = if free.0.is_empty() { val.iter().zip(&probs).map(|(s, p)| s.of_kind(p, grey)).filter(|(s, _)| s.images > 0).unzip() } else { free };
            [kind_sets(grey, false), free]
        })
        .collect();
    for k in 0..1000 {
        let thr = k as f32 / 1000.0;
        let mut row = json!({"threshold": thr});
        let mut line = format!("{thr:9.2}");
        for (g, [(vc, pc), (vf, pf)]) in sets.iter().enumerate() {
            let name = ["colour", "grey"][g];
            if vf.is_empty() {
                continue;
            }
            let (_, fp) = ap50_and_fp(vf, pf, thr);
            let (ap, _) = ap50_and_fp(vc, pc, thr);
            line += &format!("  {ap:11.3}  {fp:15.3}");
            row[format!("ap50_{name}")] = json!(ap);
            row[format!("fp_per_image_{name}")] = json!(fp);
            if chosen[g].is_none() && fp <= a.max_fp_per_frame {
                chosen[g] = Some((thr, ap, fp));
            }
        }
        if k % 50 == 0 {
            eprintln!("{line}");
        }
        table.push(row);
    }
    let has = |g: usize| !sets[g][1].0.is_empty();
    if !has(0) && !has(1) {
        bail!("no validation image");
    }
    for g in 0..2 {
        if has(g) && chosen[g].is_none() {
            bail!("no threshold below 1 gives at most {} false detections per {} validation image", a.max_fp_per_frame, ["colour", "grey"][g]);
        }
    }
    // Colour images take `threshold`; grey ones `threshold_grey` (the one threshold when the
    // validation sets hold a single kind), chosen on the detections of the searches these
    // options run: no separate cut for images searched twice.
    let (colour, grey) = (chosen[0], chosen[1]);
    v.threshold = colour.or(grey).expect("checked above").0;
    v.threshold_grey = colour.and(grey).map(|g| g.0);
    v.threshold_far = None;
    // AP50 over all validation composites with each image kind at its own cut.
    let (vc, pc): (Vec<SetSamples>, Vec<Vec<f32>>) = val
        .iter()
        .zip(&probs)
        .filter(|(s, _)| s.tubes > 0)
        .map(|(s, p)| {
            let grey: std::collections::HashSet<u64> = s.per_image.iter().filter(|i| i.2).map(|i| i.0).collect();
            let cut: Vec<f32> = s.samples.iter().zip(p).map(|(d, &p)| if p >= v.threshold_for(grey.contains(&d.image_id)) { p } else { -1.0 }).collect();
            (s.clone(), cut)
        })
        .unzip();
    let (ap, _) = ap50_and_fp(&vc, &pc, 0.0);
    let at = |c: Option<(f32, f64, f64)>| c.map(|(t, ap, fp)| json!({"threshold": t, "ap50": ap, "fp_per_image": fp}));
    v.provenance = json!({
        "weights": fitted,
        "thresholds": {
            "command": args.join(" "),
            "val": val.iter().map(|s| json!({"set": s.set, "images": s.images, "tubes": s.tubes, "detections": s.samples.len()})).collect::<Vec<_>>(),
            "rule": format!("per image kind (colour, grey), the lowest threshold on a 0.001 grid with at most {} false detections per tube-free validation image of that kind", a.max_fp_per_frame),
            "val_at_threshold": {"ap50_all_composites": ap, "colour": at(colour), "grey": at(grey)},
        },
    });
    files::write_json(&a.work.join("threshold_table.json"), &table)?;
    files::write_json(&a.out, &v)?;
    for (name, c) in [("colour", colour), ("grey", grey)] {
        if let Some((t, ap, fp)) = c {
            eprintln!("{name}: threshold {t:.3}, val AP50 {ap:.3}, {fp:.3} false detections per tube-free image");
        }
    }
    eprintln!("val AP50 of all composites at these cuts: {ap:.3} -> {}", a.out.display());
    Ok(())
}
