//! `TubeDetection`: the seed every detector hands to the pose refiner.
//!
//! A detection is one candidate tube in one image: a COCO-style record (`image_id`,
//! `category_id`, `score`, `bbox` `[x, y, w, h]` in pixels with the top-left pixel's outer corner
//! at `(-0.5, -0.5)` as COCO writes it) plus optional seeds for the refiner:
//!
//! - a mask (`segmentation`, compressed COCO RLE as pycocotools writes it),
//! - a coarse pose `T_cam_tube` (Line2D: the pose of the matched template),
//! - an [`AxisSeed`] in the image (learned segmenter, or computed from a mask),
//! - the id of the matched template and the detector that produced it ([`DetectionSource`]).
//!
//! JSON is a superset of a COCO results entry: readers that only know COCO ignore the extra
//! fields, and [`read_coco_results`] accepts plain COCO results (unknown fields are ignored).

use crate::coco::Segmentation;
use crate::error::CoreError;
use crate::mask::Rle;
use crate::pose::Pose;
use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Which detector produced a detection.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DetectionSource {
    /// Line2D template matching (carries a coarse template pose).
    Line2d,
    /// The learned segmenter (carries a mask and an axis seed).
    Learned,
    /// Imported from an external COCO results file.
    #[default]
    External,
}

/// The tube's axis as seen in the image: a segment through `centre_px` along `direction_px`.
///
/// Pixel units, pixel centres at integers. `direction_px` is a unit 2D vector; its sign is
/// arbitrary unless the detector knows which end is the seal end (then it points toward it).
/// `length_px` is the extent along the direction and `width_px` the extent across it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxisSeed {
    /// Centre of the tube's image, pixels `(u, v)`.
    pub centre_px: [f64; 2],
    /// Unit direction of the axis in the image.
    pub direction_px: [f64; 2],
    /// Length of the tube's image along the axis, pixels.
    pub length_px: f64,
    /// Width of the tube's image across the axis, pixels.
    pub width_px: f64,
}

impl AxisSeed {
    /// The principal axis of a set of pixels (e.g. a mask's foreground pixel centres).
    ///
    /// Centre = mean, direction = major eigenvector of the 2x2 second-moment matrix
    /// `C = Σ (p - m)(p - m)^T / n`, length and width = extents of the pixels along the major
    /// and minor directions plus one pixel. Returns `None` for fewer than 2 pixels.
    /// The direction sign is normalized so that its largest component is positive.
    pub fn from_pixels(pixels: impl IntoIterator<Item = (f64, f64)> + Clone) -> Option<AxisSeed> {
        let (mut n, mut sx, mut sy) = (0usize, 0.0, 0.0);
        for (x, y) in pixels.clone() {
            n += 1;
            sx += x;
            sy += y;
        }
        if n < 2 {
            return None;
        }
        let m = Vector2::new(sx / n as f64, sy / n as f64);
        let mut c = Matrix2::zeros();
        for (x, y) in pixels.clone() {
            let d = Vector2::new(x, y) - m;
            c += d * d.transpose();
        }
        c /= n as f64;
        // Major eigenvector of a symmetric 2x2 matrix in closed form.
        let (a, b, d) = (c[(0, 0)], c[(0, 1)], c[(1, 1)]);
        let theta = 0.5 * (2.0 * b).atan2(a - d);
        let mut dir = Vector2::new(theta.cos(), theta.sin());
        if dir.x.abs() >= dir.y.abs() && dir.x < 0.0 || dir.y.abs() > dir.x.abs() && dir.y < 0.0 {
            dir = -dir;
        }
        let perp = Vector2::new(-dir.y, dir.x);
        let (mut lo, mut hi, mut wlo, mut whi) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for (x, y) in pixels {
            let p = Vector2::new(x, y) - m;
            let (s, t) = (p.dot(&dir), p.dot(&perp));
            lo = lo.min(s);
            hi = hi.max(s);
            wlo = wlo.min(t);
            whi = whi.max(t);
        }
        // Centre the segment on the extent midpoint, not the mass centre (the seal end is wider).
        let mid = 0.5 * (lo + hi);
        let wmid = 0.5 * (wlo + whi);
        let centre = m + dir * mid + perp * wmid;
        Some(AxisSeed { centre_px: [centre.x, centre.y], direction_px: [dir.x, dir.y], length_px: hi - lo + 1.0, width_px: whi - wlo + 1.0 })
    }

    /// Checks finite values, a unit direction (within 1e-3) and positive sizes.
    pub fn validate(&self) -> Result<(), CoreError> {
        let v = [self.centre_px[0], self.centre_px[1], self.direction_px[0], self.direction_px[1], self.length_px, self.width_px];
        if v.iter().any(|x| !x.is_finite()) {
            return Err(CoreError::invalid("axis_seed", "non-finite value"));
        }
        let n = self.direction_px[0].hypot(self.direction_px[1]);
        if (n - 1.0).abs() > 1e-3 {
            return Err(CoreError::invalid("axis_seed", format!("direction_px must be a unit vector (norm {n:.4})")));
        }
        if self.length_px <= 0.0 || self.width_px <= 0.0 {
            return Err(CoreError::invalid("axis_seed", "length_px and width_px must be positive"));
        }
        Ok(())
    }
}

fn default_category() -> u64 {
    1
}

/// One tube candidate in one image, passed from any detector to the refiner.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TubeDetection {
    /// COCO image id.
    pub image_id: u64,
    /// COCO category id (1 = tube).
    #[serde(default = "default_category")]
    pub category_id: u64,
    /// Detector confidence; higher is more confident.
    pub score: f64,
    /// Bounding box `[x, y, w, h]`, pixels, COCO convention.
    pub bbox: [f64; 4],
    /// Instance mask, written as COCO `segmentation` in compressed RLE
    /// (`{"size": [h, w], "counts": "..."}`); uncompressed RLE (`counts` as a number list) is
    /// read too. Polygon segmentations are refused (COCO results carry RLE).
    #[serde(rename = "segmentation", default, skip_serializing_if = "Option::is_none", with = "rle_serde")]
    pub mask: Option<Rle>,
    /// Coarse pose of the tube in the camera frame (Line2D template pose), tube frame as in
    /// [`crate::tube`]: origin at the tube centre, +z toward the seal end.
    #[serde(rename = "T_cam_tube", default, skip_serializing_if = "Option::is_none")]
    pub t_cam_tube: Option<Pose>,
    /// Axis of the tube in the image (learned segmenter, or from the mask).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis_seed: Option<AxisSeed>,
    /// Id of the matched template (Line2D).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub template_id: Option<u64>,
    /// Which detector produced this detection.
    #[serde(default)]
    pub source: DetectionSource,
}

impl TubeDetection {
    /// A detection with only the COCO fields set.
    pub fn new(image_id: u64, score: f64, bbox: [f64; 4], source: DetectionSource) -> Self {
        TubeDetection { image_id, category_id: 1, score, bbox, mask: None, t_cam_tube: None, axis_seed: None, template_id: None, source }
    }

    /// Checks finite score and box, non-negative box size, a valid axis seed if present, and a
    /// mask whose counts match its size, of at most [`crate::mask::MAX_MASK_PIXELS`] pixels.
    pub fn validate(&self) -> Result<(), CoreError> {
        if !self.score.is_finite() || self.bbox.iter().any(|v| !v.is_finite()) {
            return Err(CoreError::invalid("detection", "score and bbox must be finite"));
        }
        if self.bbox[2] < 0.0 || self.bbox[3] < 0.0 {
            return Err(CoreError::invalid("detection", "bbox width and height must be non-negative"));
        }
        if let Some(a) = &self.axis_seed {
            a.validate()?;
        }
        if let Some(m) = &self.mask {
            m.check()?;
            let pixels = m.size[0] as u64 * m.size[1] as u64;
            if pixels > crate::mask::MAX_MASK_PIXELS {
                return Err(CoreError::invalid("segmentation", format!("mask size {}x{} (h x w) exceeds the limit of {} pixels", m.size[0], m.size[1], crate::mask::MAX_MASK_PIXELS)));
            }
        }
        Ok(())
    }

    /// The principal axis of the mask ([`AxisSeed::from_pixels`] over the set pixel centres);
    /// `None` without a mask or with fewer than 2 set pixels.
    pub fn axis_seed_from_mask(&self) -> Result<Option<AxisSeed>, CoreError> {
        let Some(rle) = &self.mask else { return Ok(None) };
        let m = rle.to_mask()?;
        let w = m.width;
        let px = m.data.iter().enumerate().filter(|(_, v)| **v != 0).map(move |(i, _)| ((i % w) as f64, (i / w) as f64));
        Ok(AxisSeed::from_pixels(px))
    }

    /// An axis seed from the box alone (the box diagonal that is longer; sign arbitrary):
    /// the weakest seed, used when neither a pose nor a mask is available.
    pub fn axis_seed_from_bbox(&self) -> AxisSeed {
        let [x, y, w, h] = self.bbox;
        let c = [x + 0.5 * w - 0.5, y + 0.5 * h - 0.5];
        let n = w.hypot(h).max(1e-9);
        AxisSeed { centre_px: c, direction_px: [w / n, h / n], length_px: n.max(1.0), width_px: (w.min(h)).max(1.0) }
    }
}

/// Reads a detections file: a JSON array of COCO results entries, possibly with the extra
/// fields of [`TubeDetection`]. Entries without `source` are marked `external`; entries with a
/// mask but no `axis_seed` get the mask's principal axis ([`TubeDetection::axis_seed_from_mask`]).
/// Errors name the file and the entry index.
pub fn read_coco_results(path: &Path) -> Result<Vec<TubeDetection>, CoreError> {
    let text = std::fs::read(path).map_err(|e| CoreError::io(path, e))?;
    parse_coco_results(&text, path)
}

/// Parses COCO results JSON text (see [`read_coco_results`]); `origin` names the source.
pub fn parse_coco_results(text: &[u8], origin: &Path) -> Result<Vec<TubeDetection>, CoreError> {
    let mut dets: Vec<TubeDetection> = serde_json::from_slice(text).map_err(|e| CoreError::parse(origin, format!("invalid COCO results JSON: {e}")))?;
    for (i, d) in dets.iter_mut().enumerate() {
        d.validate().map_err(|e| CoreError::parse(origin, format!("entry {i}: {e}")))?;
        if d.axis_seed.is_none() {
            d.axis_seed = d.axis_seed_from_mask().map_err(|e| CoreError::parse(origin, format!("entry {i}: {e}")))?;
        }
    }
    Ok(dets)
}

/// Serde for `Option<Rle>` as a COCO RLE segmentation (compressed on output).
mod rle_serde {
    use super::{Rle, Segmentation};
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(v: &Option<Rle>, s: S) -> Result<S::Ok, S::Error> {
        v.as_ref().map(Segmentation::from_rle).serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Rle>, D::Error> {
        use serde::de::Error;
        match Option::<Segmentation>::deserialize(d)? {
            None => Ok(None),
            Some(Segmentation::CompressedRle { size, counts }) => Rle::from_compressed_string(&counts, size).map(Some).map_err(D::Error::custom),
            Some(Segmentation::UncompressedRle { size, counts }) => {
                let rle = Rle { size, counts };
                rle.check().map_err(D::Error::custom)?;
                Ok(Some(rle))
            }
            Some(Segmentation::Polygons(_)) => Err(D::Error::custom("polygon segmentation in a results entry: COCO results carry RLE masks")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn principal_axis_of_a_rotated_bar() {
        // A 60x8 pixel bar rotated by 30 degrees around (100, 50).
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let mut px = Vec::new();
        for i in -300..300 {
            for j in -40..40 {
                let (a, b) = (i as f64 * 0.1, j as f64 * 0.1);
                px.push((100.0 + a * c - b * s, 50.0 + a * s + b * c));
            }
        }
        let seed = AxisSeed::from_pixels(px.iter().copied()).unwrap();
        assert!((seed.centre_px[0] - 100.0).abs() < 0.1 && (seed.centre_px[1] - 50.0).abs() < 0.1, "{seed:?}");
        assert!((seed.direction_px[0] - c).abs() < 1e-3 && (seed.direction_px[1] - s).abs() < 1e-3, "{seed:?}");
        assert!((seed.length_px - 60.9).abs() < 0.5 && (seed.width_px - 8.9).abs() < 0.5, "{seed:?}");
        assert!(AxisSeed::from_pixels([(1.0, 1.0)]).is_none());
    }

    #[test]
    fn reads_plain_coco_results_and_extended_fields() {
        let text = br#"[{"image_id": 3, "category_id": 1, "bbox": [10, 20, 30, 5], "score": 0.9, "extra": 1},
            {"image_id": 4, "bbox": [0, 0, 1, 1], "score": 0.1, "source": "line2d", "template_id": 7,
             "T_cam_tube": {"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0, 0, 1]}}]"#;
        let d = parse_coco_results(text, Path::new("r.json")).unwrap();
        assert_eq!(d.len(), 2);
        assert_eq!(d[0].source, DetectionSource::External);
        assert_eq!(d[1].source, DetectionSource::Line2d);
        assert_eq!(d[1].template_id, Some(7));
        assert_eq!(d[1].t_cam_tube.unwrap().translation().z, 1.0);
        let back: Vec<TubeDetection> = serde_json::from_str(&serde_json::to_string(&d).unwrap()).unwrap();
        assert_eq!(back, d);
        let bad = br#"[{"image_id": 1, "bbox": [0, 0, -1, 1], "score": 1}]"#;
        let err = parse_coco_results(bad, Path::new("r.json")).unwrap_err().to_string();
        assert!(err.contains("r.json") && err.contains("entry 0"), "{err}");
    }

    #[test]
    fn mask_round_trips_as_compressed_rle_and_seeds_the_axis() {
        use crate::mask::BinaryMask;
        // A 40x6 pixel bar at 45 degrees in a 64x48 image.
        let m = BinaryMask::from_fn(64, 48, |x, y| {
            let (u, v) = (x as f64 - 30.0, y as f64 - 20.0);
            let (s, t) = ((u + v) / 2f64.sqrt(), (v - u) / 2f64.sqrt());
            s.abs() <= 20.0 && t.abs() <= 3.0
        });
        let rle = Rle::from_mask(&m);
        let mut d = TubeDetection::new(2, 0.7, m.bbox(), DetectionSource::External);
        d.mask = Some(rle.clone());
        let text = serde_json::to_string(&[&d]).unwrap();
        assert!(text.contains(&format!("\"segmentation\":{{\"size\":[48,64],\"counts\":\"{}\"}}", rle.to_compressed_string())), "{text}");
        let back = parse_coco_results(text.as_bytes(), Path::new("m.json")).unwrap();
        assert_eq!(back[0].mask.as_ref(), Some(&rle));
        let a = back[0].axis_seed.expect("axis seed from the mask");
        assert!((a.centre_px[0] - 30.0).abs() < 0.6 && (a.centre_px[1] - 20.0).abs() < 0.6, "{a:?}");
        let h = 0.5f64.sqrt();
        assert!((a.direction_px[0].abs() - h).abs() < 0.02 && (a.direction_px[1].abs() - h).abs() < 0.02, "{a:?}");
        assert!(a.direction_px[0] * a.direction_px[1] > 0.0, "{a:?}");
        assert!((a.length_px - 41.0).abs() < 3.0 && a.width_px > 4.0 && a.width_px < 10.0, "{a:?}");
        // Uncompressed RLE is read too; a bad RLE and a polygon are refused with the entry named.
        let unc = format!("[{{\"image_id\":1,\"bbox\":[0,0,2,2],\"score\":1,\"segmentation\":{{\"size\":[48,64],\"counts\":{:?}}}}}]", rle.counts);
        assert_eq!(parse_coco_results(unc.as_bytes(), Path::new("u.json")).unwrap()[0].mask.as_ref(), Some(&rle));
        let bad = br#"[{"image_id":1,"bbox":[0,0,2,2],"score":1,"segmentation":{"size":[4,4],"counts":[3,2]}}]"#;
        let err = parse_coco_results(bad, Path::new("b.json")).unwrap_err().to_string();
        assert!(err.contains("b.json") && err.contains("counts sum to 5"), "{err}");
        let poly = br#"[{"image_id":1,"bbox":[0,0,2,2],"score":1,"segmentation":[[0,0,5,0,5,5]]}]"#;
        let err = parse_coco_results(poly, Path::new("p.json")).unwrap_err().to_string();
        assert!(err.contains("polygon"), "{err}");
    }
}
