//! A COCO dataset directory as the detectors take it: `annotations.json` read once, giving each
//! image's file, camera (checked against the image's size), ground plane and working scale.

use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tubeloc_core::{CameraModel, CocoDataset, GroundPlane};

/// A dataset directory (`annotations.json` + images) read for detection.
pub struct DetectionDataset {
    /// The directory.
    dir: PathBuf,
    /// Its `annotations.json`, named in errors.
    ann: PathBuf,
    /// The annotations as read.
    ds: CocoDataset,
    /// The cameras of the images that carry one, by image id, each checked against its
    /// image's `width` x `height`.
    cameras: BTreeMap<u64, CameraModel>,
}

impl DetectionDataset {
    /// Reads `dir/annotations.json` and every image's `camera`; a camera that does not parse,
    /// or that describes images of another size than its image's, is an error naming the image
    /// (rather than leaving that image at the wrong scale, silently).
    pub fn load(dir: &Path) -> Result<Self> {
        let ann = dir.join("annotations.json");
        let ds = CocoDataset::load(&ann).with_context(|| format!("reading {}", ann.display()))?;
        let mut cameras = BTreeMap::new();
        for im in &ds.images {
            if let Some(c) = im.extra.get("camera") {
                let cam: CameraModel = serde_json::from_value(c.clone()).with_context(|| format!("{}: image {} ({}): camera", ann.display(), im.id, im.file_name))?;
                if (cam.width, cam.height) != (im.width, im.height) {
                    bail!("{}: image {} ({}) is {}x{} px but its camera describes {}x{} px images", ann.display(), im.id, im.file_name, im.width, im.height, cam.width, cam.height);
                }
                cameras.insert(im.id, cam);
            }
        }
        Ok(Self { dir: dir.to_path_buf(), ann, ds, cameras })
    }

    /// The annotations as read.
    pub fn coco(&self) -> &CocoDataset {
        &self.ds
    }

    /// Its `annotations.json`.
    pub fn annotations_path(&self) -> &Path {
        &self.ann
    }

    /// The images as `(image_id, path)`: the file beside `annotations.json`, else in `images/`.
    pub fn images(&self) -> Vec<(u64, PathBuf)> {
        self.ds
            .images
            .iter()
            .map(|im| {
                let p = self.dir.join(&im.file_name);
                (im.id, if p.exists() { p } else { self.dir.join("images").join(&im.file_name) })
            })
            .collect()
    }

    /// The cameras of the images that carry one, by image id.
    pub fn cameras(&self) -> &BTreeMap<u64, CameraModel> {
        &self.cameras
    }

    /// The ground planes of the images that carry one (`images[].ground`, as `tubeloc synth
    /// real` writes it; [`tubeloc_detect::learned::dataset::image_ground`]), by image id.
    pub fn grounds(&self) -> BTreeMap<u64, GroundPlane> {
        self.ds.images.iter().filter_map(|im| Some((im.id, tubeloc_detect::learned::dataset::image_ground(im)?))).collect()
    }

    /// How many images carry no `camera` (detected as they are, not at the detectors' scale).
    pub fn cameraless(&self) -> usize {
        self.ds.images.len() - self.cameras.len()
    }

    /// The learned detector's working scale of each of `images` (ids of this dataset) for the
    /// range band `band` (as [`tubeloc_detect::learned::dataset::image_working_scale`]); 1 for an
    /// image without a camera, or for every image with the band "off" (`None`).
    pub fn working_scales(&self, images: &[(u64, PathBuf)], band: Option<tubeloc_detect::scale::RangeBand>) -> Vec<f64> {
        let Some(band) = band else { return vec![1.0; images.len()] };
        let by_id: std::collections::HashMap<u64, &tubeloc_core::CocoImage> = self.ds.images.iter().map(|im| (im.id, im)).collect();
        let scale = |id: &u64| {
            let (cam, im) = (self.cameras.get(id)?, by_id.get(id)?);
            Some(tubeloc_detect::scale::working_scale(cam, tubeloc_detect::learned::dataset::ground_field(im), band))
        };
        images.iter().map(|(id, _)| scale(id).unwrap_or(1.0)).collect()
    }
}
