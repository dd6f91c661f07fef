//! COCO dataset and results files: serde types that keep unknown fields, loaders with
//! validation, and conversion of segmentations to [`Rle`] as pycocotools' `annToRLE` does.
//!
//! Attributes tubeloc adds (terrain, time of day, occlusion, ...) live in the `extra` maps and
//! are written back unchanged.

use crate::error::CoreError;
use crate::mask::Rle;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use std::path::Path;

/// A COCO dataset (ground truth): images, annotations and categories.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CocoDataset {
    /// Free-form `info` block.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub info: Option<Value>,
    /// Free-form `licenses` block.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub licenses: Option<Value>,
    /// Images.
    pub images: Vec<CocoImage>,
    /// Object annotations.
    #[serde(default)]
    pub annotations: Vec<CocoAnnotation>,
    /// Categories.
    #[serde(default)]
    pub categories: Vec<CocoCategory>,
    /// Unknown top-level fields, preserved.
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// One image of a COCO dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CocoImage {
    /// Image id, unique in the dataset.
    pub id: u64,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// File name relative to the dataset's image folder.
    #[serde(default)]
    pub file_name: String,
    /// Other fields (tubeloc image attributes: terrain, time, camera height, split...).
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// One category.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CocoCategory {
    /// Category id.
    pub id: u64,
    /// Category name.
    #[serde(default)]
    pub name: String,
    /// Other fields (`supercategory`...).
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// One ground-truth object annotation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CocoAnnotation {
    /// Annotation id (pycocotools treats id 0 as "no match" during evaluation; use ids >= 1).
    pub id: u64,
    /// Id of the image the object is in.
    pub image_id: u64,
    /// Category id.
    pub category_id: u64,
    /// Object outline (polygons or RLE); needed for `segm` evaluation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segmentation: Option<Segmentation>,
    /// Object area in pixels; COCO evaluation uses this field for the area ranges.
    pub area: f64,
    /// Box `[x, y, w, h]` in pixels.
    pub bbox: [f64; 4],
    /// 1 for a crowd region (matches many detections, never a false negative).
    #[serde(default)]
    pub iscrowd: u8,
    /// Other fields (tubeloc annotation attributes: occlusion, dust, pose...).
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// A segmentation as COCO stores it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Segmentation {
    /// Polygons `[[x0, y0, x1, y1, ...], ...]` in pixels (the first needs at least 6 numbers:
    /// pycocotools cannot rasterize a list whose first polygon has 4 or fewer).
    Polygons(Vec<Vec<f64>>),
    /// Compressed RLE: `size = [h, w]`, `counts` in the `rleToString` alphabet.
    CompressedRle {
        /// `[h, w]`.
        size: [u32; 2],
        /// Compressed counts.
        counts: String,
    },
    /// Uncompressed RLE: `size = [h, w]`, column-major run lengths.
    UncompressedRle {
        /// `[h, w]`.
        size: [u32; 2],
        /// Run lengths.
        counts: Vec<u32>,
    },
}

impl Segmentation {
    /// Converts to an [`Rle`] for an image of `h x w` pixels (`annToRLE`): polygons are
    /// rasterized and merged, RLEs decoded. An RLE whose size is not `[h, w]` is an error.
    pub fn to_rle(&self, h: u32, w: u32) -> Result<Rle, CoreError> {
        match self {
            Segmentation::Polygons(polys) => {
                let Some(first) = polys.first() else {
                    return Err(CoreError::invalid("segmentation", "empty polygon list"));
                };
                if first.len() <= 4 {
                    // pycocotools' frPyObjects reads such a list as boxes (4) or rejects it (< 4).
                    return Err(CoreError::invalid("segmentation", format!("polygon 0 has {} numbers; a polygon needs at least 6", first.len())));
                }
                if let Some(bad) = polys.iter().flatten().find(|v| !v.is_finite()) {
                    return Err(CoreError::invalid("segmentation", format!("non-finite polygon coordinate {bad}")));
                }
                Rle::from_polygons(polys, h, w)
            }
            Segmentation::CompressedRle { size, counts } => {
                check_size(*size, h, w)?;
                Rle::from_compressed_string(counts, *size)
            }
            Segmentation::UncompressedRle { size, counts } => {
                check_size(*size, h, w)?;
                let rle = Rle { size: *size, counts: counts.clone() };
                rle.check()?;
                Ok(rle)
            }
        }
    }

    /// The compressed-RLE segmentation of `rle`.
    pub fn from_rle(rle: &Rle) -> Segmentation {
        Segmentation::CompressedRle { size: rle.size, counts: rle.to_compressed_string() }
    }
}

fn check_size(size: [u32; 2], h: u32, w: u32) -> Result<(), CoreError> {
    if size != [h, w] {
        return Err(CoreError::invalid("segmentation", format!("mask size [h, w] = {size:?} differs from the image size [{h}, {w}]")));
    }
    Ok(())
}

/// One detection in a COCO results file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CocoResult {
    /// Image id (must exist in the ground truth).
    pub image_id: u64,
    /// Category id.
    pub category_id: u64,
    /// Confidence; higher is better.
    pub score: f64,
    /// Mask, for `segm` evaluation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segmentation: Option<Segmentation>,
    /// Box `[x, y, w, h]` in pixels, for `bbox` evaluation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bbox: Option<[f64; 4]>,
    /// Other fields, preserved.
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

impl CocoDataset {
    /// Loads and validates a dataset file. Errors name the file and, for a bad entry, its list,
    /// index and id: malformed JSON, duplicate image ids, annotations on unknown images,
    /// non-finite numbers, masks whose size differs from their image.
    pub fn load(path: &Path) -> Result<CocoDataset, CoreError> {
        let text = std::fs::read(path).map_err(|e| CoreError::io(path, e))?;
        let ds: CocoDataset = match serde_json::from_slice(&text) {
            Ok(ds) => ds,
            Err(e) => return Err(explain_dataset_error(path, &text, e)),
        };
        ds.validate().map_err(|m| CoreError::parse(path, m))?;
        Ok(ds)
    }

    /// Checks ids, sizes and numbers; the message names the entry.
    pub fn validate(&self) -> Result<(), String> {
        let mut sizes = std::collections::HashMap::with_capacity(self.images.len());
        for (i, img) in self.images.iter().enumerate() {
            if sizes.insert(img.id, (img.height, img.width)).is_some() {
                return Err(format!("images[{i}] (id {}): duplicate image id", img.id));
            }
        }
        for (i, a) in self.annotations.iter().enumerate() {
            let at = || format!("annotations[{i}] (id {})", a.id);
            let Some(&(h, w)) = sizes.get(&a.image_id) else {
                return Err(format!("{}: unknown image_id {}", at(), a.image_id));
            };
            if !a.area.is_finite() || a.bbox.iter().any(|v| !v.is_finite()) {
                return Err(format!("{}: non-finite area or bbox", at()));
            }
            if let Some(seg) = &a.segmentation {
                seg.to_rle(h, w).map_err(|e| format!("{}: {e}", at()))?;
            }
        }
        Ok(())
    }

    /// Writes the dataset as JSON, atomically.
    pub fn save(&self, path: &Path) -> Result<(), CoreError> {
        crate::files::write_json(path, self)
    }
}

/// Loads a results file (a JSON array of [`CocoResult`]) and validates it against `gt`: every
/// `image_id` must be a ground-truth image, scores and boxes finite, masks of the image's size.
/// Errors name the file and the entry (index, image id).
pub fn load_results(path: &Path, gt: &CocoDataset) -> Result<Vec<CocoResult>, CoreError> {
    let text = std::fs::read(path).map_err(|e| CoreError::io(path, e))?;
    let results: Vec<CocoResult> = match serde_json::from_slice(&text) {
        Ok(r) => r,
        Err(e) => return Err(explain_list_error(path, &text, e)),
    };
    validate_results(&results, gt).map_err(|m| CoreError::parse(path, m))?;
    Ok(results)
}

/// Checks results against `gt` (see [`load_results`]); the message names the entry.
pub fn validate_results(results: &[CocoResult], gt: &CocoDataset) -> Result<(), String> {
    let sizes: std::collections::HashMap<u64, (u32, u32)> = gt.images.iter().map(|im| (im.id, (im.height, im.width))).collect();
    for (i, r) in results.iter().enumerate() {
        let at = || format!("results[{i}] (image_id {})", r.image_id);
        let Some(&(h, w)) = sizes.get(&r.image_id) else {
            return Err(format!("{}: image_id {} is not in the ground truth", at(), r.image_id));
        };
        if !r.score.is_finite() {
            return Err(format!("{}: non-finite score", at()));
        }
        if let Some(bb) = r.bbox {
            if bb.iter().any(|v| !v.is_finite()) {
                return Err(format!("{}: non-finite bbox", at()));
            }
        }
        if let Some(seg) = &r.segmentation {
            seg.to_rle(h, w).map_err(|e| format!("{}: {e}", at()))?;
        }
    }
    Ok(())
}

/// Re-parses a dataset that failed typed parsing entry by entry to name the bad entry.
fn explain_dataset_error(path: &Path, text: &[u8], e: serde_json::Error) -> CoreError {
    let Ok(Value::Object(top)) = serde_json::from_slice::<Value>(text) else {
        return CoreError::parse(path, format!("invalid JSON: {e}"));
    };
    for key in ["images", "annotations", "categories"] {
        let Some(Value::Array(items)) = top.get(key) else { continue };
        let msg = match key {
            "images" => first_bad::<CocoImage>(key, items),
            "annotations" => first_bad::<CocoAnnotation>(key, items),
            _ => first_bad::<CocoCategory>(key, items),
        };
        if let Some(m) = msg {
            return CoreError::parse(path, m);
        }
    }
    CoreError::parse(path, format!("invalid COCO dataset: {e}"))
}

/// Re-parses a results file that failed typed parsing entry by entry to name the bad entry.
fn explain_list_error(path: &Path, text: &[u8], e: serde_json::Error) -> CoreError {
    match serde_json::from_slice::<Value>(text) {
        Ok(Value::Array(items)) => match first_bad::<CocoResult>("results", &items) {
            Some(m) => CoreError::parse(path, m),
            None => CoreError::parse(path, format!("invalid COCO results: {e}")),
        },
        Ok(_) => CoreError::parse(path, "COCO results must be a JSON array of detections"),
        Err(_) => CoreError::parse(path, format!("invalid JSON: {e}")),
    }
}

fn first_bad<T: serde::de::DeserializeOwned>(key: &str, items: &[Value]) -> Option<String> {
    items.iter().enumerate().find_map(|(i, v)| {
        serde_json::from_value::<T>(v.clone()).err().map(|err| {
            let id = ["id", "image_id"].iter().find_map(|k| v.get(*k).map(|x| format!(" ({k} {x})"))).unwrap_or_default();
            format!("{key}[{i}]{id}: {err}")
        })
    })
}
