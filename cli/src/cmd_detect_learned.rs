//! The `learned` and `external` methods of `tubeloc detect`: run the learned segmenter, or
//! pass COCO results made elsewhere through, writing COCO results (mask RLE, bbox, score) plus
//! each instance's `axis_seed` and `source` (the fields of `tubeloc_core::TubeDetection`).

use crate::detect_dataset::DetectionDataset;
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};
use tubeloc_core::{CocoResult, DetectionSource, Segmentation, TubeDetection};
use tubeloc_detect::learned::{detect_rgb_at_scale, DecodeConfig, LearnedModel};

/// One output entry: a COCO result with the detection's seed fields.
#[derive(Serialize)]
pub struct DetectionOut {
    #[serde(flatten)]
    det: TubeDetection,
    segmentation: Option<Segmentation>,
}

/// The learned model a command runs: a file given with `--model`, or the shipped model, which
/// is embedded in the program (`data/models/tubenet.safetensors` when it was built), so an
/// installed or copied `tubeloc` needs no data folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelChoice {
    /// The shipped model, embedded in the program.
    Shipped,
    /// A model file.
    File(PathBuf),
}

impl ModelChoice {
    /// `--model FILE` when given, else the shipped model.
    pub fn of(arg: Option<&Path>) -> Self {
        arg.map_or(ModelChoice::Shipped, |p| ModelChoice::File(p.to_path_buf()))
    }

    /// The model's name in reports and messages: the file, or the shipped model's file name
    /// marked as embedded.
    pub fn name(&self) -> String {
        match self {
            ModelChoice::Shipped => format!("{} (embedded)", tubeloc_detect::learned::shipped::SHIPPED_MODEL_NAME),
            ModelChoice::File(p) => p.display().to_string(),
        }
    }

    /// Parses the model (checked: format, version, checksum, shapes).
    pub fn load(&self) -> Result<LearnedModel> {
        match self {
            ModelChoice::Shipped => tubeloc_detect::learned::shipped_model().context("loading the embedded shipped model"),
            ModelChoice::File(p) => {
                if !p.exists() {
                    bail!("learned model {} not found: pass an existing --model FILE, or leave --model out to use the shipped model", p.display());
                }
                LearnedModel::load(p).with_context(|| format!("loading model {}", p.display()))
            }
        }
    }

    /// The pipeline's learned detector with this model.
    pub fn detector(&self) -> Result<tubeloc_pipeline::LearnedDetector> {
        Ok(tubeloc_pipeline::LearnedDetector::new(self.load()?, Default::default(), self.name()))
    }

    /// The model file, or `None` for the shipped model (what `--model` holds).
    pub fn path(&self) -> Option<&Path> {
        match self {
            ModelChoice::Shipped => None,
            ModelChoice::File(p) => Some(p),
        }
    }

    /// The score calibration of this model: `path` when given; else for a model file
    /// `<model>.calibration.json` beside it, or the identity (probability = score, threshold
    /// 0.5) with a warning when there is none; for the shipped model its embedded calibration
    /// (`data/models/tubenet.calibration.json`).
    pub fn calibration(&self, path: Option<&Path>) -> Result<tubeloc_core::ScoreCalibration> {
        let model = match self {
            ModelChoice::Shipped => None,
            ModelChoice::File(p) => Some(p.as_path()),
        };
        Ok(tubeloc_pipeline::shipped::load_calibration(path, model)?)
    }
}

/// Parses a tube-range band ([`tubeloc_pipeline::shipped::parse_range_band`]).
pub fn parse_range_band(s: &str) -> Result<Option<tubeloc_detect::scale::RangeBand>> {
    Ok(tubeloc_pipeline::shipped::parse_range_band(s)?)
}

/// Images to process: `(image_id, path)`: `--image` (with `image_id`) or a dataset's.
pub fn image_list(image: Option<&Path>, image_id: u64, dataset: Option<&DetectionDataset>) -> Result<Vec<(u64, PathBuf)>> {
    match (image, dataset) {
        (Some(p), None) => Ok(vec![(image_id, p.to_path_buf())]),
        (None, Some(d)) => Ok(d.images()),
        _ => bail!("give exactly one of --image or --dataset"),
    }
}

/// The working scale of each image ([`tubeloc_detect::scale`]): from each dataset image's
/// `camera` and `ground`, or for one image from `--camera` and `--ground`; 1 without a camera
/// or with the band "off".
pub fn working_scales(images: &[(u64, PathBuf)], dataset: Option<&DetectionDataset>, camera: Option<&Path>, ground: Option<&tubeloc_core::GroundPlane>, band: Option<tubeloc_detect::scale::RangeBand>) -> Result<Vec<f64>> {
    let Some(band) = band else { return Ok(vec![1.0; images.len()]) };
    if let Some(d) = dataset {
        return Ok(d.working_scales(images, Some(band)));
    }
    let ground = ground.map(|g| (g.normal, g.offset));
    let Some(cam) = camera else {
        if ground.is_some() {
            bail!("--ground needs --camera (the working scale comes from the camera's focal length)");
        }
        return Ok(vec![1.0; images.len()]);
    };
    let cam = tubeloc_core::CameraModel::load_json(cam).with_context(|| format!("reading camera {}", cam.display()))?;
    Ok(vec![tubeloc_detect::scale::working_scale(&cam, ground, band); images.len()])
}

/// Runs the learned model over images, each at its working scale (`scales[i]`, 1 = as it
/// is); returns the output entries.
pub fn run_learned(model: &ModelChoice, images: &[(u64, PathBuf)], scales: &[f64], cfg: &DecodeConfig) -> Result<Vec<DetectionOut>> {
    let model = model.load()?;
    let pb = ProgressBar::new(images.len() as u64);
    pb.set_style(ProgressStyle::with_template("detect {bar:30} {pos}/{len} {elapsed}<{eta}").expect("template"));
    let per: Vec<Vec<DetectionOut>> = images
        .iter()
        .zip(scales)
        .map(|((id, p), &s)| {
            let image = tubeloc_detect::input::open_image(p).map_err(|e| anyhow::anyhow!("reading image {}: {e}", p.display()))?;
            if let Some(warn) = crate::cmd_detect::underexposure_warning(p, &image) {
                pb.suspend(|| eprintln!("{warn}"));
            }
            let input = tubeloc_detect::input::rgb8_of(&image);
            drop(image);
            let (w, h) = (input.width, input.height);
            if let Some(warn) = input.info.warning() {
                pb.suspend(|| eprintln!("warning: {}: {warn}", p.display()));
            }
            let inst = detect_rgb_at_scale(&model, &input.rgb, w, h, s, cfg).with_context(|| format!("detecting in {}", p.display()))?;
            pb.inc(1);
            Ok(inst
                .into_par_iter()
                .map(|i| {
                    let rle = i.mask;
                    let mut det = TubeDetection::new(*id, i.score, i.bbox, DetectionSource::Learned);
                    det.axis_seed = Some(i.axis);
                    DetectionOut { det, segmentation: Some(Segmentation::from_rle(&rle)) }
                })
                .collect())
        })
        .collect::<Result<_>>()?;
    pb.finish_and_clear();
    Ok(per.into_iter().flatten().collect())
}

/// Passes external COCO results through: the mask's principal axis becomes the axis seed (the
/// box diagonal when there is no mask). Polygon masks need the image size: `--image` or
/// `--dataset` gives it.
pub fn run_external(results: &Path, sizes: &(dyn Fn(u64) -> Option<(u32, u32)> + Sync)) -> Result<Vec<DetectionOut>> {
    let text = std::fs::read(results).with_context(|| format!("reading {}", results.display()))?;
    let list: Vec<CocoResult> = serde_json::from_slice(&text).with_context(|| format!("{}: not a COCO results list", results.display()))?;
    list.into_par_iter()
        .enumerate()
        .map(|(k, r)| {
            let ctx = format!("{}: entry {k} (image {})", results.display(), r.image_id);
            let mut det = tubeloc_pipeline::detector::detection_from_coco_result(&r, sizes(r.image_id), &ctx).map_err(|e| anyhow::anyhow!("{e}"))?;
            // The mask travels as the result's own segmentation.
            det.mask = None;
            Ok(DetectionOut { det, segmentation: r.segmentation })
        })
        .collect()
}
