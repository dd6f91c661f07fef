//! `Line2dDetection`: one detection with its template, coarse 6D pose and COCO output.
//!
//! Coarse pose: the matched template was rendered with the tube centre on the optical axis
//! (ray `r0 = (0, 0, 1)`). At the detection the centre appears at pixel `p = (x, y) + c_t`
//! (template top-left plus the template's centre offset), whose ray is `r1 = unproject(p)`.
//! The pose is `T_cam_tube = R(r0 → r1) · T_template`, with `R(r0 → r1)` the smallest rotation
//! taking `r0` to `r1`: the tube keeps its distance and its orientation relative to the line of
//! sight.

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
    /// Detection score in 0..=1 (the COCO score): `similarity / 100` without verification,
    /// else the verified score `(similarity / 100 + w clamp(C, -1, 1)) / (1 + w)`
    /// (see [`crate::line2d::verify`]).
    pub score: f32,
    /// Luminance contrast `C` of the silhouette against a ring around it, when verified.
    pub contrast: Option<f32>,
    /// Column of the placed template's top-left pixel.
    pub x: i32,
    /// Row of the placed template's top-left pixel.
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
        let (tw, th) = (t.levels[0].width as i64, t.levels[0].height as i64);
        let (w, h) = (width as i64, height as i64);
        let (x0, y0) = ((m.x as i64).clamp(0, w), (m.y as i64).clamp(0, h));
        let (x1, y1) = ((m.x as i64 + tw).clamp(0, w), (m.y as i64 + th).clamp(0, h));
        let inside = |x: u32, y: u32| {
            let (lx, ly) = (x as i64 - m.x as i64, y as i64 - m.y as i64);
            t.mask[(ly * tw + lx) as usize] != 0
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
        let centre_px = [m.x as f64 + t.centre[0] as f64, m.y as f64 + t.centre[1] as f64];
        let t_cam_tube = adjust_pose(&t.t_cam_tube, camera, centre_px);
        Line2dDetection { template_id: t.id, similarity: m.score, score: m.score / 100.0, contrast: None, x: m.x, y: m.y, bbox, centre_px, t_cam_tube, mask }
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
