//! Reading calibration sets written by `tubeloc synth calib` (`calib_set.json`) into
//! [`CalibrationInput`], with corners taken from the file (exact or noisy) or detected in the
//! rendered images.

use crate::calibrate::{CalibrationInput, CameraSpec, Observation};
use crate::detect::{DetectorConfig, TagFamily};
use crate::error::CalibError;
use nalgebra::{Point2, Point3};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;
use tubeloc_core::Rig;

/// A tag board: tag centres in the board frame (x right, y down, z into the board).
#[derive(Clone, Debug, Deserialize)]
pub struct Board {
    /// Family of all tags.
    pub family: TagFamily,
    /// Edge of each tag's black square, metres.
    pub tag_size_m: f64,
    /// Tags.
    pub tags: Vec<BoardTag>,
}

/// One board tag.
#[derive(Clone, Debug, Deserialize)]
pub struct BoardTag {
    /// Id.
    pub id: u32,
    /// Centre `[x, y]`, metres.
    pub centre: [f64; 2],
}

impl Board {
    /// Board-frame corners of tag `id` in the detector's order, or `None` if not on the board.
    pub fn corners(&self, id: u32) -> Option<[Point3<f64>; 4]> {
        let t = self.tags.iter().find(|t| t.id == id)?;
        Some(crate::mount::tag_corners(self.tag_size_m).map(|p| Point3::new(p.x + t.centre[0], p.y + t.centre[1], 0.0)))
    }
}

#[derive(Deserialize)]
struct TagCornersJson {
    id: u32,
    corners: [[f64; 2]; 4],
}

#[derive(Deserialize)]
struct ObsJson {
    camera: String,
    image: Option<String>,
    exact: Vec<TagCornersJson>,
    noisy: Vec<TagCornersJson>,
}

#[derive(Deserialize)]
struct ViewJson {
    index: usize,
    observations: Vec<ObsJson>,
}

#[derive(Deserialize)]
struct SetJson {
    board: Board,
    rig: Rig,
    views: Vec<ViewJson>,
}

/// Where the image corners come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CornerSource {
    /// The exact corners in the file.
    Exact,
    /// The noisy corners in the file.
    Noisy,
    /// Detect tags in the rendered images.
    Detect,
}

/// A loaded calibration set: the calibration input plus the true rig stored beside it.
#[derive(Clone, Debug)]
pub struct LoadedSet {
    /// Observations ready for [`crate::calibrate::calibrate`].
    pub input: CalibrationInput,
    /// The board.
    pub board: Board,
    /// The rig the set was generated with (truth, at the set's resolution).
    pub truth: Rig,
}

/// Reads `dir/calib_set.json`; with [`CornerSource::Detect`] detects the tags of its images
/// with `detector` ([`crate::batch::detect_files`]: `detector.threads` images at once).
pub fn load_calib_set(dir: &Path, source: CornerSource, detector: Option<&DetectorConfig>) -> Result<LoadedSet, CalibError> {
    load_calib_set_reporting(dir, source, detector, &|_| {})
}

/// [`load_calib_set`], calling `on_image(n)` as each of the `n` images to detect in is done
/// (for a progress bar; not called for corners read from the file).
pub fn load_calib_set_reporting(dir: &Path, source: CornerSource, detector: Option<&DetectorConfig>, on_image: &(dyn Fn(usize) + Sync)) -> Result<LoadedSet, CalibError> {
    let path = dir.join("calib_set.json");
    let set: SetJson = tubeloc_core::files::read_json(&path)?;
    let cameras: Vec<CameraSpec> = set.rig.cameras.iter().map(|c| CameraSpec { name: c.name.clone(), width: c.model.width, height: c.model.height }).collect();
    let index: BTreeMap<&str, usize> = cameras.iter().enumerate().map(|(i, c)| (c.name.as_str(), i)).collect();
    // Every observation's camera (and, to detect, its image) is checked before any is read.
    let mut seen = Vec::new();
    for v in &set.views {
        for o in &v.observations {
            let cam = *index.get(o.camera.as_str()).ok_or_else(|| CalibError::parse(&path, format!("views[{}]: unknown camera {:?}", v.index, o.camera)))?;
            seen.push((v.index, cam, o));
        }
    }
    let tags: Vec<Vec<(u32, [[f64; 2]; 4])>> = match source {
        CornerSource::Exact => seen.iter().map(|(_, _, o)| o.exact.iter().map(|t| (t.id, t.corners)).collect()).collect(),
        CornerSource::Noisy => seen.iter().map(|(_, _, o)| o.noisy.iter().map(|t| (t.id, t.corners)).collect()).collect(),
        CornerSource::Detect => {
            let config = detector.ok_or_else(|| CalibError::invalid("detector", "corner source Detect needs a detector"))?;
            let images = seen
                .iter()
                .map(|(view, _, o)| o.image.as_ref().map(|name| dir.join(name)).ok_or_else(|| CalibError::parse(&path, format!("views[{view}] camera {}: no image to detect in (set made without rendering)", o.camera))))
                .collect::<Result<Vec<_>, _>>()?;
            let found = crate::batch::detect_files(config, &images, &|| on_image(images.len()))?;
            found.into_iter().map(|f| f.map(|d| d.into_iter().map(|d| (d.id, d.corners)).collect())).collect::<Result<_, _>>()?
        }
    };
    let mut observations = Vec::new();
    for ((view, cam, _), tags) in seen.into_iter().zip(tags) {
        let mut ob = Observation { camera: cam, view, object: Vec::new(), image: Vec::new() };
        for (id, corners) in tags {
            let Some(obj) = set.board.corners(id) else { continue };
            for (p, c) in obj.iter().zip(&corners) {
                ob.object.push(*p);
                ob.image.push(Point2::new(c[0], c[1]));
            }
        }
        if !ob.object.is_empty() {
            observations.push(ob);
        }
    }
    let input = CalibrationInput { cameras, observations, stereo_pairs: set.rig.stereo_pairs.clone() };
    Ok(LoadedSet { input, board: set.board, truth: set.rig })
}
