//! `tubeloc train`: train the learned tube segmenter on COCO dataset directories.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use tubeloc_detect::learned::augment::AugmentConfig;
use tubeloc_detect::learned::dataset::{ap50, load_coco_dir};
use tubeloc_detect::learned::{DecodeConfig, LearnedModel, Preprocess, TrainConfig, Trainer};

/// Arguments of `tubeloc train`.
#[derive(clap::Args)]
pub struct TrainArgs {
    /// Training dataset directory (annotations.json + images); repeat for several.
    #[arg(long, required = true)]
    pub train: Vec<PathBuf>,
    /// Validation dataset directory (AP50 shown in the progress bar).
    #[arg(long)]
    pub val: Option<PathBuf>,
    /// Output weights (safetensors); checkpoints go to `<out>.ckpt`.
    #[arg(long)]
    pub out: PathBuf,
    /// Epochs (one epoch = as many crop pixels as the training set has pixels).
    #[arg(long, default_value_t = 20)]
    pub epochs: u64,
    /// Total optimizer steps (overrides --epochs).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Seed of the weight initialization and of the crop sampler.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Resume from a checkpoint or model file (its architecture and preprocessing win).
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Input preprocessing: gray-box (paper), gray-box:R, or rgb.
    #[arg(long, default_value = "gray-box")]
    pub preprocess: String,
    /// Base width of the network.
    #[arg(long, default_value_t = 8)]
    pub width: usize,
    /// Crops per step.
    #[arg(long, default_value_t = 8)]
    pub batch: usize,
    /// Crop side, pixels (multiple of 32).
    #[arg(long, default_value_t = 256)]
    pub crop: usize,
    /// Peak learning rate.
    #[arg(long, default_value_t = 2e-3)]
    pub lr: f64,
    /// Validate every this many steps (and at the end).
    #[arg(long, default_value_t = 250)]
    pub val_every: u64,
    /// Use at most this many validation images.
    #[arg(long, default_value_t = 40)]
    pub val_limit: usize,
    /// Write a checkpoint every this many steps.
    #[arg(long, default_value_t = 250)]
    pub ckpt_every: u64,
    /// Use at most this many images of each training set.
    #[arg(long)]
    pub train_limit: Option<usize>,
}

/// Runs `tubeloc train`.
pub fn run(args: TrainArgs) -> Result<()> {
    let pre = Preprocess::parse(&args.preprocess).with_context(|| format!("unknown --preprocess {:?} (gray-box, gray-box:R, rgb)", args.preprocess))?;
    let model = match &args.resume {
        Some(p) => LearnedModel::load(p).with_context(|| format!("resuming from {}", p.display()))?,
        None => LearnedModel::new(pre, args.width, args.seed)?,
    };
    let pre = model.meta.preprocess;
    let mut images = Vec::new();
    for d in &args.train {
        let mut v = load_coco_dir(d, pre, args.train_limit).with_context(|| format!("loading training set {}", d.display()))?;
        eprintln!("{}: {} images", d.display(), v.len());
        images.append(&mut v);
    }
    if images.is_empty() {
        bail!("no training images");
    }
    let val = match &args.val {
        Some(d) => load_coco_dir(d, pre, Some(args.val_limit)).with_context(|| format!("loading validation set {}", d.display()))?,
        None => Vec::new(),
    };
    let pixels: usize = images.iter().map(|i| i.width * i.height).sum();
    let per_epoch = (pixels as f64 / (args.crop * args.crop * args.batch) as f64).ceil().max(1.0) as u64;
    let total = args.steps.unwrap_or(args.epochs * per_epoch);
    let cfg = TrainConfig {
        batch: args.batch,
        lr: args.lr,
        total_steps: total,
        seed: args.seed,
        augment: AugmentConfig { crop: args.crop, ..Default::default() },
        ..Default::default()
    };
    let mut trainer = Trainer::new(model, cfg)?;
    let start = trainer.model.meta.steps;
    let ckpt = PathBuf::from(format!("{}.ckpt", args.out.display()));
    let pb = ProgressBar::new(total);
    pb.set_style(ProgressStyle::with_template("train {bar:30} {pos}/{len} {elapsed}<{eta} {msg}").expect("template"));
    pb.set_position(start.min(total));
    let (mut ema, mut last_ap) = (f32::NAN, f64::NAN);
    let validate = |t: &Trainer| -> Result<f64> { if val.is_empty() { Ok(f64::NAN) } else { Ok(ap50(&t.model, &val, &DecodeConfig::default())?) } };
    while trainer.model.meta.steps < total {
        let l = trainer.step(&images)?;
        ema = if ema.is_nan() { l } else { 0.95 * ema + 0.05 * l };
        let k = trainer.model.meta.steps;
        if k % args.val_every == 0 {
            last_ap = validate(&trainer)?;
        }
        if k % args.ckpt_every == 0 {
            trainer.model.save(&ckpt).with_context(|| format!("writing checkpoint {}", ckpt.display()))?;
        }
        pb.set_position(k);
        pb.set_message(format!("loss {ema:.4} val AP50 {last_ap:.3}"));
    }
    pb.finish();
    let ap = validate(&trainer)?;
    trainer.model.meta.notes = format!("steps {} seed {} val AP50 {ap:.4}", trainer.model.meta.steps, args.seed);
    trainer.model.save(&args.out).with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("saved {} ({} steps, loss {ema:.4}, val AP50 {ap:.4})", args.out.display(), trainer.model.meta.steps);
    Ok(())
}
