//! `Line2dDetection`: one detection with its template, coarse 6D pose and COCO output.
//!
//! Coarse pose: the matched template was rendered with the tube centre on the optical axis
//! (ray `r0 = (0, 0, 1)`). At the detection the centre appears at pixel `p = (x, y) + c_t`
//! (template top-left plus the template's centre offset), whose ray is `r1 = unproject(p)`.
//! The pose is `T_cam_tube = R(r0 → r1) · T_template`, with `R(r0 → r1)` the smallest rotation
//! taking `r0` to `r1`: the tube keeps its distance and its orientation relative to the line of
//! sight.

use crate::line2d::classify::Features;
use crate::line2d::mask::rle_from_box;
use crate::line2d::matching::RawMatch;
use crate::line2d::template::Template;
use nalgebra::{Point2, Rotation3, Vector3};
use serde_json::json;
use tubeloc_core::detection::{DetectionSource, TubeDetection};
use tubeloc_core::Rle;
use tubeloc_core::{CameraModel, Pose};

/// A Line2D detection in one image.
#[derive(Clone, Debug, PartialEq)]
pub struct Line2dDetection {
    /// Id of the matched template in its library.
    pub template_id: u32,
    /// Line2D similarity, percent of the maximum (0..100).
    pub similarity: f32,
    /// Detection score in 0..=1 (the COCO score): the verifier's probability when it ran
    /// (see [`crate::line2d::classify`]), else `similarity / 100` without radiometric
    /// verification, else the verified score `(similarity / 100 + w clamp(C, -1, 1)) / (1 + w)`
    /// (see [`crate::line2d::verify`]).
    pub score: f32,
    /// Luminance contrast `C` of the silhouette against a ring around it, when verified.
    pub contrast: Option<f32>,
    /// Calibrated probability of being a tube from the clutter verifier
    /// ([`crate::line2d::classify`]), when it ran; it is then also the `score`.
    pub probability: Option<f32>,
    /// The verifier's features of this detection, when it ran.
    pub features: Option<Features>,
    /// Probability that the pose refined from this detection is a tube, when the detection was
    /// verified by its pose (`tubeloc_pipeline::pose_verifier`); the `score` is then this
    /// probability, and `mask` and `bbox` are the refined pose's silhouette where it agrees
    /// with the template's (the mask snapped to the pose).
    pub pose_probability: Option<f32>,
    /// Factor by which the image was resampled to the library's pixel scale before matching
    /// (geometric mean over the two axes; 1 = matched as given).
    pub scale: f64,
    /// Column of the placed template's top-left pixel, in the original image (rounded when
    /// the image was resampled).
    pub x: i32,
    /// Row of the placed template's top-left pixel, in the original image (rounded when the
    /// image was resampled).
    pub y: i32,
    /// COCO box `[x, y, w, h]` of the placed silhouette clipped to the image, pixels
    /// (`x` = first column index, `w` = number of columns, as pycocotools' `toBbox`).
    pub bbox: [f64; 4],
    /// Image position of the tube centre, pixels.
    pub centre_px: [f64; 2],
    /// Coarse pose `T_cam_tube` (metres).
    pub t_cam_tube: Pose,
    /// The placed template silhouette as a COCO RLE over the whole image.
    pub mask: Rle,
}

impl Line2dDetection {
    /// Builds the detection of match `m` of template `t` in a `width x height` image.
    pub fn from_match(m: &RawMatch, t: &Template, camera: &CameraModel, width: usize, height: usize) -> Self {
        Self::from_match_scaled(m, t, camera, width, height, 1.0, 1.0)
    }

    /// Builds the detection of match `m` of template `t` found in the image resampled by
    /// `(sx, sy)` (resampled size / original size, per axis), mapped back to the original
    /// `width x height` image of camera `camera`: original pixel `(u, v)` belongs to the mask
    /// when the resampled pixel nearest its centre, `(round((u + ½) sx - ½), round((v + ½) sy
    /// - ½))`, lies in the placed silhouette (as [`crate::scale::mask_back`]); the centre maps
    /// back by [`crate::scale::point_back`] and the coarse pose is that of the template turned
    /// onto the centre's ray in `camera` (a ray does not change under resampling, so the pose
    /// equals the one in the resampled camera). With `sx = sy = 1` this is the plain placement.
    pub fn from_match_scaled(m: &RawMatch, t: &Template, camera: &CameraModel, width: usize, height: usize, sx: f64, sy: f64) -> Self {
        let (tw, th) = (t.levels[0].width as i64, t.levels[0].height as i64);
        let (w, h) = (width as i64, height as i64);
        // Original pixels whose nearest resampled pixel can lie in [m.x, m.x + tw) x [m.y, m.y + th).
        let lo = |a: i64, s: f64, n: i64| (((a as f64) / s - 0.5).ceil() as i64 - 1).clamp(0, n);
        let hi = |b: i64, s: f64, n: i64| (((b as f64) / s - 0.5).ceil() as i64 + 1).clamp(0, n);
        let (x0, x1, y0, y1) = if sx == 1.0 && sy == 1.0 {
            ((m.x as i64).clamp(0, w), (m.x as i64 + tw).clamp(0, w), (m.y as i64).clamp(0, h), (m.y as i64 + th).clamp(0, h))
        } else {
            (lo(m.x as i64, sx, w), hi(m.x as i64 + tw, sx, w), lo(m.y as i64, sy, h), hi(m.y as i64 + th, sy, h))
        };
        let inside = |x: u32, y: u32| {
            let (xs, ys) = if sx == 1.0 && sy == 1.0 { (x as i64, y as i64) } else { (((x as f64 + 0.5) * sx - 0.5).round() as i64, ((y as f64 + 0.5) * sy - 0.5).round() as i64) };
            let (lx, ly) = (xs - m.x as i64, ys - m.y as i64);
            lx >= 0 && ly >= 0 && lx < tw && ly < th && t.mask[(ly * tw + lx) as usize] != 0
        };
        let mask = rle_from_box(height as u32, width as u32, x0 as u32, x1 as u32, y0 as u32, y1 as u32, inside);
        let (mut bx0, mut by0, mut bx1, mut by1) = (i64::MAX, i64::MAX, -1, -1);
        for y in y0..y1 {
            for x in x0..x1 {
                if inside(x as u32, y as u32) {
                    bx0 = bx0.min(x);
                    by0 = by0.min(y);
                    bx1 = bx1.max(x);
                    by1 = by1.max(y);
                }
            }
        }
        let bbox = if bx1 < 0 { [x0 as f64, y0 as f64, 0.0, 0.0] } else { [bx0 as f64, by0 as f64, (bx1 - bx0 + 1) as f64, (by1 - by0 + 1) as f64] };
        let centre_px = crate::scale::point_back([m.x as f64 + t.centre[0] as f64, m.y as f64 + t.centre[1] as f64], sx, sy);
        let corner = crate::scale::point_back([m.x as f64, m.y as f64], sx, sy);
        let t_cam_tube = adjust_pose(&t.t_cam_tube, camera, centre_px);
        Line2dDetection {
            template_id: t.id,
            similarity: m.score,
            score: m.score / 100.0,
            contrast: None,
            probability: None,
            features: None,
            pose_probability: None,
            scale: (sx * sy).sqrt(),
            x: corner[0].round() as i32,
            y: corner[1].round() as i32,
            bbox,
            centre_px,
            t_cam_tube,
            mask,
        }
    }

    /// The core detection record (score, coarse pose, template id).
    pub fn to_tube_detection(&self, image_id: u64) -> TubeDetection {
        let mut d = TubeDetection::new(image_id, self.score as f64, self.bbox, DetectionSource::Line2d);
        d.t_cam_tube = Some(self.t_cam_tube);
        d.template_id = Some(self.template_id as u64);
        d.mask = Some(self.mask.clone());
        d
    }

    /// A COCO results entry: the [`TubeDetection`] fields plus `segmentation` (compressed RLE).
    pub fn to_coco_json(&self, image_id: u64) -> serde_json::Value {
        let mut v = serde_json::to_value(self.to_tube_detection(image_id)).unwrap_or_else(|_| json!({}));
        if let Some(o) = v.as_object_mut() {
            o.insert("similarity".into(), json!(self.similarity));
            if let Some(c) = self.contrast {
                o.insert("contrast".into(), json!(c));
            }
            if let Some(p) = self.probability {
                o.insert("probability".into(), json!(p));
            }
            if let Some(p) = self.pose_probability {
                o.insert("pose_probability".into(), json!(p));
            }
            if let Some(f) = &self.features {
                o.insert("verifier_features".into(), json!(f.to_vec()));
            }
            if self.scale != 1.0 {
                o.insert("scale".into(), json!(self.scale));
            }
        }
        v
    }
}

/// Rotates a template pose (tube centre on the optical axis) so that the centre's ray passes
/// through pixel `centre_px` of `camera`.
pub fn adjust_pose(t_template: &Pose, camera: &CameraModel, centre_px: [f64; 2]) -> Pose {
    let r1 = camera.unproject(&Point2::new(centre_px[0], centre_px[1]));
    let r = Rotation3::rotation_between(&Vector3::z(), &r1).unwrap_or_else(Rotation3::identity);
    Pose::from_parts(r, Vector3::zeros()) * *t_template
}
