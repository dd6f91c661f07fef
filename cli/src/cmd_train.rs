//! `tubeloc train`: train the learned tube segmenter on COCO dataset directories and/or on
//! freshly rendered scenes (`--generate N`, cached in a folder, seeds disjoint from the paper
//! benchmark's).

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use tubeloc_detect::learned::augment::AugmentConfig;
use tubeloc_detect::learned::dataset::{ap50, load_coco_dir, load_coco_dir_at_scale};
use tubeloc_detect::learned::{DecodeConfig, LearnedModel, Preprocess, TrainConfig, Trainer};

/// Arguments of `tubeloc train`.
#[derive(clap::Args)]
pub struct TrainArgs {
    /// Training dataset directory (annotations.json + images); repeat for several.
    #[arg(long)]
    pub train: Vec<PathBuf>,
    /// Also train on N freshly rendered images of the paper preset's terrains and conditions
    /// (scene seeds from --gen-seed, checked disjoint from the benchmark's seed 0), rendered
    /// once into --gen-dir and reused when it already holds them.
    #[arg(long, value_parser = crate::args::positive_usize)]
    pub generate: Option<usize>,
    /// Master seed of the generated scenes (must differ from the benchmark's 0).
    #[arg(long, default_value_t = 1)]
    pub gen_seed: u64,
    /// Crop side of the generated images, pixels (the paper preset's scale 0.5; smaller crops
    /// render faster and training crops are smaller still).
    #[arg(long, default_value_t = 512, value_parser = crate::args::positive_u32)]
    pub gen_crop: u32,
    /// Cache folder of the generated images (default `<out>.gen`).
    #[arg(long)]
    pub gen_dir: Option<PathBuf>,
    /// Validation dataset directory (AP50 shown in the progress bar).
    #[arg(long)]
    pub val: Option<PathBuf>,
    /// Output weights (safetensors); checkpoints go to `<out>.ckpt`.
    #[arg(long)]
    pub out: PathBuf,
    /// Epochs (one epoch = as many crop pixels as the training set has pixels).
    #[arg(long, default_value_t = 20, value_parser = crate::args::positive_u64)]
    pub epochs: u64,
    /// Total optimizer steps (overrides --epochs).
    #[arg(long, value_parser = crate::args::positive_u64)]
    pub steps: Option<u64>,
    /// Seed of the weight initialization and of the crop sampler.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Resume from a checkpoint (`<out>.ckpt`, with its optimizer state `<out>.ckpt.opt`) or a
    /// model file (fresh optimizer moments); its architecture and preprocessing win.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Warm start: copy every tensor of this trained model whose name and shape the new model
    /// has (e.g. to add the --fine-mask branch); its preprocessing and width win, and the step
    /// count and schedule start from 0.
    #[arg(long, conflicts_with = "resume")]
    pub init: Option<PathBuf>,
    /// With --init of a gray-box model: train an RGB model (`--preprocess rgb`) started from it,
    /// its input convolution applied to the luma of the three channels
    /// (`LearnedModel::init_from_gray`).
    #[arg(long, requires = "init")]
    pub init_rgb: bool,
    /// With --init: start from the --init model widened to this base width, computing what it
    /// computes (`LearnedModel::widened`, Net2WiderNet), so fine-tuning adds capacity without
    /// losing the trained model's accuracy.
    #[arg(long, requires = "init", value_parser = crate::args::positive_usize)]
    pub widen: Option<usize>,
    /// Add the full-resolution mask branch (mask outlines at pixel precision instead of
    /// bilinear stride-4 logits); kept when the --init model has it.
    #[arg(long)]
    pub fine_mask: bool,
    /// Train only the fine mask branch; the other layers keep the --init model's weights.
    #[arg(long, requires = "init")]
    pub freeze_coarse: bool,
    /// Input preprocessing: gray-norm (grey, normalized by the image's own percentiles: one
    /// model for grey and colour cameras), gray-box (paper), gray-box:R, or rgb. With --init,
    /// the init model's unless given (a one-channel model may change between gray-box and
    /// gray-norm).
    #[arg(long)]
    pub preprocess: Option<String>,
    /// Camera-like appearance randomization of every crop (tone curve, blur, vignetting,
    /// sensor noise).
    #[arg(long)]
    pub photometric: bool,
    /// Train each image at its working scale (from its camera and ground plane, as inference
    /// resamples it; `tubeloc synth real` sets carry both): the tube-range band "NEAR:FAR" in
    /// metres, or "off".
    #[arg(long, default_value = "1:4", value_parser = crate::args::range_band)]
    pub range_m: String,
    /// Base width of the network.
    #[arg(long, default_value_t = 8, value_parser = crate::args::positive_usize)]
    pub width: usize,
    /// Crops per step.
    #[arg(long, default_value_t = 8, value_parser = crate::args::positive_usize)]
    pub batch: usize,
    /// Crop side, pixels (multiple of 32).
    #[arg(long, default_value_t = 256, value_parser = crop_arg)]
    pub crop: usize,
    /// Keep training crops upright (no 90-degree turns; left-right mirror only), so that the
    /// network can learn that a tube's contact shadow lies on its far (image-up) side.
    #[arg(long)]
    pub upright: bool,
    /// Probability that a training crop gets random occluders (1 to 3 rectangles of flat
    /// or block-patterned fill whose pixels become background; 0 = off).
    #[arg(long, default_value_t = 0.0, value_parser = crate::args::unit_interval)]
    pub occluders: f64,
    /// Probability that a training crop is seen as by a camera with 1.5-3 times coarser pixels
    /// (averaged, noised at that resolution and enlarged back, as inference enlarges a coarse
    /// camera's frame to the working scale; 0 = off)
    #[arg(long, default_value_t = 0.0, value_parser = crate::args::unit_interval)]
    pub resolution_drop: f64,
    /// Peak learning rate.
    #[arg(long, default_value_t = 2e-3, value_parser = crate::args::positive_f64)]
    pub lr: f64,
    /// Validate every this many steps (and at the end).
    #[arg(long, default_value_t = 250, value_parser = crate::args::positive_u64)]
    pub val_every: u64,
    /// Use at most this many validation images.
    #[arg(long, default_value_t = 40, value_parser = crate::args::positive_usize)]
    pub val_limit: usize,
    /// Write a checkpoint every this many steps.
    #[arg(long, default_value_t = 250, value_parser = crate::args::positive_u64)]
    pub ckpt_every: u64,
    /// Use at most this many images of each training set.
    #[arg(long, value_parser = crate::args::positive_usize)]
    pub train_limit: Option<usize>,
    /// Instead of training, write the uniform average of these models' weights to --out (a
    /// "model soup": fine-tunings of one --init model with different --seed values; same
    /// architecture and preprocessing required). With --val, its AP50 is reported.
    #[arg(long, num_args = 2.., value_name = "MODEL", conflicts_with_all = ["train", "generate", "resume", "init"])]
    pub average: Vec<PathBuf>,
}

/// `--crop`: a positive multiple of 32 (the network's input stride).
fn crop_arg(s: &str) -> std::result::Result<usize, String> {
    let n = crate::args::positive_usize(s)?;
    if n % 32 == 0 {
        Ok(n)
    } else {
        Err(format!("must be a positive multiple of 32, got {n}"))
    }
}

/// `tubeloc train --average`: the weight average of the given models, saved to `out`.
fn average_models(args: &TrainArgs) -> Result<()> {
    let mut models = Vec::new();
    for p in &args.average {
        models.push(LearnedModel::load(p).with_context(|| format!("reading --average model {}", p.display()))?);
    }
    let names: Vec<String> = args.average.iter().map(|p| p.display().to_string()).collect();
    let numbered: Vec<String> = names.iter().enumerate().map(|(k, n)| format!("model {} = {n}", k + 1)).collect();
    let mut soup = tubeloc_detect::learned::weight_average(&models).with_context(|| format!("averaging {}", numbered.join(", ")))?;
    // The library names the count and the first model's notes; the files come from here.
    soup.meta.notes = format!("{} (files: {})", soup.meta.notes, names.join(", "));
    if let Some(d) = &args.val {
        let val = load_coco_dir(d, soup.meta.preprocess, Some(args.val_limit)).with_context(|| format!("loading validation set {}", d.display()))?;
        eprintln!("val AP50 {:.4} ({} images of {})", ap50(&soup, &val, &DecodeConfig::default())?, val.len(), d.display());
    }
    soup.save(&args.out).with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("saved {} (average of {} models)", args.out.display(), models.len());
    Ok(())
}

/// Renders (or reuses) the generated training set: `n` images spread over
/// `max(15, n / 16)` scenes cycling through the paper preset's terrains and times.
fn generated_set(n: usize, seed: u64, crop: u32, dir: &std::path::Path) -> Result<()> {
    use tubeloc_synth::DatasetSpec;
    if seed == 0 {
        bail!("--gen-seed 0 is the benchmark's seed; pick another");
    }
    let ann = dir.join("annotations.json");
    if ann.exists() {
        let ds = tubeloc_core::CocoDataset::load(&ann).with_context(|| format!("reading {}", ann.display()))?;
        if ds.images.len() == n {
            eprintln!("{}: reusing {} generated images", dir.display(), n);
            return Ok(());
        }
        bail!("{} holds {} images, not {n}: remove it or pick another --gen-dir", dir.display(), ds.images.len());
    }
    let bench: Vec<u64> = DatasetSpec::preset("paper", 0)?.scenes.iter().map(|s| s.seed).collect();
    let scenes = (n / 16).max(15);
    let mut spec = DatasetSpec::preset("paper", seed)?.with_scenes(scenes)?;
    spec.crop = crop;
    for (k, s) in spec.scenes.iter_mut().enumerate() {
        s.images = n / scenes + usize::from(k < n % scenes);
        if bench.contains(&s.seed) {
            bail!("generated scene {k} has the benchmark's scene seed {}; pick another --gen-seed", s.seed);
        }
    }
    spec.scenes.retain(|s| s.images > 0);
    let pb = ProgressBar::new(n as u64);
    pb.set_style(ProgressStyle::with_template("render {bar:30} {pos}/{len} {elapsed}<{eta}").expect("template"));
    tubeloc_synth::write_dataset(&spec, dir, (0, 1), false, &|done, _| pb.set_position(done as u64)).with_context(|| format!("rendering the generated set into {}", dir.display()))?;
    pb.finish_and_clear();
    Ok(())
}

/// Runs `tubeloc train`.
pub fn run(args: TrainArgs) -> Result<()> {
    if !args.average.is_empty() {
        return average_models(&args);
    }
    let pre_arg = args.preprocess.as_deref().unwrap_or("gray-box");
    let pre = Preprocess::parse(pre_arg).with_context(|| format!("unknown --preprocess {pre_arg:?} (gray-norm, gray-box, gray-box:R, rgb)"))?;
    let band = crate::cmd_detect_learned::parse_range_band(&args.range_m)?;
    if !(0.0..=1.0).contains(&args.occluders) {
        bail!("--occluders {} is not a probability (0 to 1)", args.occluders);
    }
    let mut dirs = args.train.clone();
    if let Some(n) = args.generate {
        let dir = args.gen_dir.clone().unwrap_or_else(|| PathBuf::from(format!("{}.gen", args.out.display())));
        generated_set(n, args.gen_seed, args.gen_crop, &dir)?;
        dirs.push(dir);
    }
    if dirs.is_empty() {
        bail!("nothing to train on: give --train DATASET and/or --generate N");
    }
    let init = match &args.init {
        Some(p) => {
            let m = LearnedModel::load(p).with_context(|| format!("reading the --init model {}", p.display()))?;
            match args.widen {
                Some(w) => Some(m.widened(w, args.seed).with_context(|| format!("--widen {w}: widening the --init model {}", p.display()))?),
                None => Some(m),
            }
        }
        None => None,
    };
    let pre = match (&args.resume, &init) {
        (Some(p), _) => LearnedModel::load(p).with_context(|| format!("resuming from {}", p.display()))?.meta.preprocess,
        (None, Some(_)) if args.init_rgb => Preprocess::Rgb,
        (None, Some(m)) if args.preprocess.is_some() && m.meta.preprocess.channels() == pre.channels() => pre,
        (None, Some(m)) => m.meta.preprocess,
        (None, None) => pre,
    };
    let mut images = Vec::new();
    for d in &dirs {
        let mut v = load_coco_dir_at_scale(d, pre, args.train_limit, band).with_context(|| format!("loading training set {}", d.display()))?;
        eprintln!("{}: {} images", d.display(), v.len());
        images.append(&mut v);
    }
    if images.is_empty() {
        bail!("no training images");
    }
    let val = match &args.val {
        Some(d) => load_coco_dir_at_scale(d, pre, Some(args.val_limit), band).with_context(|| format!("loading validation set {}", d.display()))?,
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
        augment: AugmentConfig { crop: args.crop, upright: args.upright, occluders: args.occluders, photometric: args.photometric, resolution_drop: args.resolution_drop, ..Default::default() },
        ..Default::default()
    };
    let mut trainer = match &args.resume {
        Some(p) => {
            let (t, had_opt) = Trainer::resume(p, cfg).with_context(|| format!("resuming from {}", p.display()))?;
            eprintln!("resuming at step {} ({})", t.model.meta.steps, if had_opt { "with optimizer state" } else { "no optimizer state found: fresh moments" });
            t
        }
        None => {
            let width = init.as_ref().map_or(args.width, |m| m.meta.net.width);
            let fine_mask = args.fine_mask || init.as_ref().is_some_and(|m| m.meta.net.fine_mask);
            let mut model = LearnedModel::with_fine_mask(pre, width, fine_mask, args.seed)?;
            if let (Some(m), Some(p), true) = (&init, &args.init, args.init_rgb) {
                let n = model.init_from_gray(m).with_context(|| format!("--init-rgb from {}", p.display()))?;
                eprintln!("warm start (gray -> rgb): {n} tensors from {} ({} steps)", p.display(), m.meta.steps);
            } else if let (Some(m), Some(p)) = (&init, &args.init) {
                let n = model.init_from(m)?;
                eprintln!("warm start: {n} tensors from {} ({} steps)", p.display(), m.meta.steps);
            }
            if args.freeze_coarse {
                if !model.meta.net.fine_mask {
                    bail!("--freeze-coarse trains only the fine mask branch: add --fine-mask");
                }
                model.freeze_coarse(true);
            }
            Trainer::new(model, cfg)?
        }
    };
    let start = trainer.model.meta.steps;
    let ckpt = PathBuf::from(format!("{}.ckpt", args.out.display()));
    let pb = ProgressBar::new(total);
    pb.set_style(ProgressStyle::with_template("train {bar:30} {pos}/{len} {elapsed}<{eta} {msg}").expect("template"));
    pb.set_position(start.min(total));
    let (mut ema, mut last_ap) = (f32::NAN, f64::NAN);
    let validate = |t: &Trainer| -> Result<f64> {
        if val.is_empty() {
            Ok(f64::NAN)
        } else {
            Ok(ap50(&t.model, &val, &DecodeConfig::default())?)
        }
    };
    let t0 = std::time::Instant::now();
    while trainer.model.meta.steps < total {
        let l = trainer.step(&images)?;
        ema = if ema.is_nan() { l } else { 0.95 * ema + 0.05 * l };
        let k = trainer.model.meta.steps;
        if k % args.val_every == 0 {
            last_ap = validate(&trainer)?;
            let line = format!("step {k}: loss {ema:.4} val AP50 {last_ap:.3} ({:.0} s)", t0.elapsed().as_secs_f64());
            if pb.is_hidden() {
                eprintln!("{line}");
            } else {
                pb.println(line);
            }
        }
        if k % args.ckpt_every == 0 {
            trainer.save_checkpoint(&ckpt).with_context(|| format!("writing checkpoint {}", ckpt.display()))?;
        }
        pb.set_position(k);
        pb.set_message(format!("loss {ema:.4} val AP50 {last_ap:.3}"));
    }
    pb.finish();
    let ap = validate(&trainer)?;
    let warm = match (&init, &args.init) {
        (Some(m), Some(p)) => {
            let widened = args.widen.map_or(String::new(), |w| format!(", widened to width {w}"));
            format!(" warm start from {} ({} steps{widened})", p.display(), m.meta.steps)
        }
        _ => String::new(),
    };
    let crops = if args.upright { " upright crops" } else { "" };
    let crops = if args.occluders > 0.0 { format!("{crops} occluders {}", args.occluders) } else { crops.to_string() };
    let crops = if args.resolution_drop > 0.0 { format!("{crops} resolution drop {}", args.resolution_drop) } else { crops };
    trainer.model.meta.notes = format!("steps {} seed {}{crops} val AP50 {ap:.4}{warm}", trainer.model.meta.steps, args.seed);
    trainer.model.save(&args.out).with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("saved {} ({} steps, loss {ema:.4}, val AP50 {ap:.4}, {:.0} s this run)", args.out.display(), trainer.model.meta.steps, t0.elapsed().as_secs_f64());
    Ok(())
}
