//! `tubeloc synth negatives`: hard negatives for training, mined on the real backgrounds of
//! one split (`tubeloc_detect::learned::hard_negatives`).

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use std::path::PathBuf;
use tubeloc_core::files;
use tubeloc_detect::learned::hard_negatives::{negative_centres, working_scale_crops};
use tubeloc_synth::dataset::write_folder_atomically;
use tubeloc_synth::real_frames::{read_manifest, split_of_sol, RealSplit};

/// Arguments of `tubeloc synth negatives`.
#[derive(Args)]
pub struct NegativesArgs {
    /// The real data folder (holding MANIFEST.tsv and backgrounds/).
    #[arg(long, default_value = "../shared/data/real_mars")]
    pub data: PathBuf,
    /// Part of the data whose backgrounds (no tube in any) are searched; crops of `val` or
    /// `test` frames must never be trained on.
    #[arg(long, default_value = "train")]
    pub split: RealSplit,
    /// The learned model that searches them (default: the shipped model, embedded).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Its score calibration (default: the shipped one for the shipped model, else
    /// `<model>.calibration.json` beside the model file).
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Least calibrated probability of a detection to be cut out.
    #[arg(long, default_value_t = 0.2)]
    pub min_probability: f64,
    /// Side of the crops, pixels at the frame's working scale.
    #[arg(long, default_value_t = 320, value_parser = clap::value_parser!(u32).range(32..=2048))]
    pub crop: u32,
    /// Least distance between two crop centres of one frame, pixels of the frame.
    #[arg(long, default_value_t = 128.0)]
    pub spacing_px: f64,
    /// Distances of the tubes from the camera, "NEAR:FAR" metres, for the working scale (as
    /// `tubeloc detect --range-m`).
    #[arg(long, default_value = "1:4")]
    pub range_m: String,
    /// Search at most this many frames (in the manifest's order), e.g. for a small test.
    #[arg(long)]
    pub limit: Option<usize>,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
    /// Output folder: the crops and an `annotations.json` without annotations; each image names
    /// its frame (`source`), the frame's working scale and the frame's gray-norm map (`gray_norm`:
    /// median and gain), with which `tubeloc train --preprocess gray-norm` normalizes the crop as
    /// inference normalizes the whole frame.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `tubeloc synth negatives`: each background of the split is seen under the assumed
/// view of its kind (navcam for a grey frame, mast for a colour one, the views the real
/// composites of `tubeloc synth real` are made under),
/// searched at its working scale, and a crop cut around each detection whose probability
/// reaches the floor.
pub fn run(a: NegativesArgs) -> Result<()> {
    if !(0.0..=1.0).contains(&a.min_probability) {
        bail!("--min-probability {} is not a probability in [0, 1]", a.min_probability);
    }
    if a.split != RealSplit::Train {
        eprintln!("warning: --split {}: these crops are of frames held out for choosing and reporting; never train on them", a.split.name());
    }
    let model_choice = crate::cmd_detect_learned::ModelChoice::of(a.model.as_deref());
    if let (Some(m), None) = (&a.model, &a.calibration) {
        let beside = m.with_extension("calibration.json");
        if !beside.exists() {
            bail!("no score calibration for {} ({} is missing): give --calibration, fitted with `tubeloc eval --calibrate` on that model's validation detections", m.display(), beside.display());
        }
    }
    let calibration = model_choice.calibration(a.calibration.as_deref())?;
    let band = crate::cmd_detect_learned::parse_range_band(&a.range_m)?.context("--range-m off: the crops need a working scale")?;
    let model = model_choice.load()?;
    // The crops need the detections' centres and scores only, not their masks' shape.
    let centres_only = tubeloc_detect::learned::DecodeConfig { rectangle_below_px: 0.0, ..Default::default() };
    let manifest = a.data.join("MANIFEST.tsv");
    let frames: Vec<PathBuf> = read_manifest(&manifest)?.into_iter().filter(|e| e.split == "backgrounds" && split_of_sol(e.sol) == a.split).map(|e| e.file).take(a.limit.unwrap_or(usize::MAX)).collect();
    if frames.is_empty() {
        bail!("{}: no backgrounds of split {:?}", manifest.display(), a.split);
    }
    let pb = ProgressBar::new(frames.len() as u64);
    pb.set_style(ProgressStyle::with_template("search {bar:30} {pos}/{len} {elapsed}<{eta}").expect("template"));
    let (mut searched, mut with_crops) = (0usize, 0usize);
    let summary = write_folder_atomically(&a.out, a.force, |tmp| {
        std::fs::create_dir_all(tmp.join("images")).map_err(|e| tubeloc_core::CoreError::io(tmp, e))?;
        let mut images = Vec::new();
        for f in &frames {
            let path = a.data.join(f);
            let input = tubeloc_detect::input::load(&path).map_err(tubeloc_synth::SynthError::Invalid)?;
            let (w, h) = (input.width, input.height);
            let (_, view) = tubeloc_core::AssumedView::of_kind(input.info.grey);
            let (rig, ground) = view.rig("frame", w as u32, h as u32)?;
            let s = tubeloc_detect::scale::working_scale(&rig.cameras[0].model, Some((ground.normal, ground.offset)), band);
            let found = tubeloc_detect::learned::detect_rgb_at_scale(&model, &input.rgb, w, h, s, &centres_only).map_err(|e| tubeloc_synth::SynthError::Invalid(format!("{}: {e}", path.display())))?;
            let centres = negative_centres(&found, |p| calibration.probability(p), a.min_probability, a.spacing_px);
            let stem = f.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            searched += 1;
            with_crops += usize::from(!centres.is_empty());
            // Inference normalizes the whole frame (gray-norm); each crop carries that map
            // (fitted only for frames that give crops).
            let (p50, inv) = match centres.is_empty() {
                true => (0.0, 0.0),
                false => tubeloc_detect::learned::preprocess::GrayNormMap::fit(&input.rgb, w * h).parts(),
            };
            for (k, crop) in working_scale_crops(&input.rgb, w, h, s, &centres, a.crop as usize).into_iter().enumerate() {
                let name = format!("{:05}_{stem}_{k}.png", images.len() + 1);
                let mut png = Vec::new();
                crop.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).map_err(|e| tubeloc_synth::SynthError::Invalid(format!("encoding {name}: {e}")))?;
                files::write_atomic(&tmp.join("images").join(&name), &png)?;
                images.push(json!({"id": images.len() + 1, "file_name": name, "width": crop.width(), "height": crop.height(), "source": f, "working_scale": s, "gray_norm": {"p50": p50, "inv": inv}}));
            }
            pb.inc(1);
        }
        let n = images.len();
        let doc = json!({
            "info": {"description": "tubeloc hard negatives: crops of tube-free real frames around a learned model's detections", "split": a.split.name(), "model": model_choice.name(), "min_probability": a.min_probability, "crop": a.crop, "range_m": a.range_m},
            "images": images, "annotations": [], "categories": [{"id": 1, "name": "tube", "supercategory": "object"}],
        });
        files::write_json(&tmp.join("annotations.json"), &doc)?;
        Ok((n, 0))
    })?;
    pb.finish_and_clear();
    eprintln!("{} crops from {with_crops} of {searched} frames of split {} (probability >= {}) -> {}", summary.images, a.split.name(), a.min_probability, summary.out.display());
    Ok(())
}
