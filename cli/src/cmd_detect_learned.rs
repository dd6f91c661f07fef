//! The `learned` and `external` methods of `tubeloc detect`: run the learned segmenter, or
//! pass COCO results made elsewhere through, writing COCO results (mask RLE, bbox, score) plus
//! each instance's `axis_seed` and `source` (the fields of `tubeloc_core::TubeDetection`).

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};
use tubeloc_core::{CocoDataset, CocoResult, DetectionSource, Segmentation, TubeDetection};
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

/// The cameras of a dataset's images (`images[].camera`, written by `tubeloc synth`; images
/// without one are left out) and the ground planes of those that carry one (`images[].ground`,
/// as `tubeloc synth real` writes it; [`tubeloc_detect::learned::dataset::image_ground`]), by
/// image id, from one read of the file. A camera that does not parse, or that describes images
/// of another size than its image's `width` x `height`, is an error naming the image.
#[allow(clippy::type_complexity)]
pub fn dataset_cameras_and_grounds(dataset: &Path) -> Result<(std::collections::BTreeMap<u64, tubeloc_core::CameraModel>, std::collections::BTreeMap<u64, tubeloc_core::GroundPlane>)> {
    let ann = dataset.join("annotations.json");
    let ds = CocoDataset::load(&ann).with_context(|| format!("reading {}", ann.display()))?;
    let cameras = dataset_cameras(&ds, &ann)?;
    let grounds = ds.images.iter().filter_map(|im| Some((im.id, tubeloc_detect::learned::dataset::image_ground(im)?))).collect();
    Ok((cameras, grounds))
}

/// The cameras of `ds`'s images (read from `ann`), by image id; a camera that does not parse,
/// or that describes images of another size than its image's, is an error naming the image.
fn dataset_cameras(ds: &CocoDataset, ann: &Path) -> Result<std::collections::BTreeMap<u64, tubeloc_core::CameraModel>> {
    let mut cameras = std::collections::BTreeMap::new();
    for im in &ds.images {
        if let Some(c) = im.extra.get("camera") {
            let cam: tubeloc_core::CameraModel = serde_json::from_value(c.clone()).with_context(|| format!("{}: image {} ({}): camera", ann.display(), im.id, im.file_name))?;
            if (cam.width, cam.height) != (im.width, im.height) {
                bail!("{}: image {} ({}) is {}x{} px but its camera describes {}x{} px images", ann.display(), im.id, im.file_name, im.width, im.height, cam.width, cam.height);
            }
            cameras.insert(im.id, cam);
        }
    }
    Ok(cameras)
}

/// Parses a tube-range band ([`tubeloc_pipeline::shipped::parse_range_band`]).
pub fn parse_range_band(s: &str) -> Result<Option<tubeloc_detect::scale::RangeBand>> {
    Ok(tubeloc_pipeline::shipped::parse_range_band(s)?)
}

/// Images to process: `(image_id, path)`.
pub fn image_list(image: Option<&Path>, image_id: u64, dataset: Option<&Path>) -> Result<Vec<(u64, PathBuf)>> {
    match (image, dataset) {
        (Some(p), None) => Ok(vec![(image_id, p.to_path_buf())]),
        (None, Some(d)) => {
            let ann = d.join("annotations.json");
            let ds = CocoDataset::load(&ann).with_context(|| format!("reading {}", ann.display()))?;
            Ok(ds
                .images
                .iter()
                .map(|im| {
                    let p = d.join(&im.file_name);
                    (im.id, if p.exists() { p } else { d.join("images").join(&im.file_name) })
                })
                .collect())
        }
        _ => bail!("give exactly one of --image or --dataset"),
    }
}

/// The working scale of each image ([`tubeloc_detect::scale`]): from each dataset image's
/// `camera` and `ground`, or for one image from `--camera` and `--ground`; 1 without a camera
/// or with the band "off".
pub fn working_scales(images: &[(u64, PathBuf)], dataset: Option<&Path>, camera: Option<&Path>, ground: Option<&tubeloc_core::GroundPlane>, band: Option<tubeloc_detect::scale::RangeBand>) -> Result<Vec<f64>> {
    let Some(band) = band else { return Ok(vec![1.0; images.len()]) };
    if let Some(d) = dataset {
        // Every camera read and checked against its image's size (a camera that does not
        // parse would otherwise leave its image at scale 1, silently).
        let ann = d.join("annotations.json");
        let ds = CocoDataset::load(&ann).with_context(|| format!("reading {}", ann.display()))?;
        dataset_cameras(&ds, &ann)?;
        let by_id: std::collections::HashMap<u64, &tubeloc_core::CocoImage> = ds.images.iter().map(|im| (im.id, im)).collect();
        return Ok(images.iter().map(|(id, _)| by_id.get(id).map_or(1.0, |im| tubeloc_detect::learned::dataset::image_working_scale(im, band))).collect());
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
