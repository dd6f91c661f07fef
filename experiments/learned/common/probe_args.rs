//! The command line shared by the learned probes: `MODEL DATASET_DIR [LIMIT]`.
use std::path::Path;
use tubeloc_detect::learned::dataset::load_coco_dir;
use tubeloc_detect::learned::{LearnedModel, TrainImage};

/// Loads the model and the first `LIMIT` (default `default_limit`) images of the dataset,
/// preprocessed as the model expects; `name` is the probe's name for the usage message.
pub fn model_and_images(name: &str, default_limit: usize) -> Result<(LearnedModel, Vec<TrainImage>), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 3 {
        return Err(format!("usage: {name} MODEL DATASET_DIR [LIMIT]").into());
    }
    let model = LearnedModel::load(Path::new(&a[1]))?;
    let limit = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(default_limit);
    let imgs = load_coco_dir(Path::new(&a[2]), model.meta.preprocess, Some(limit))?;
    Ok((model, imgs))
}
