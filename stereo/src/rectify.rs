//! Rectification of a calibrated stereo pair (Bouguet-style).
//!
//! Both cameras are rotated about their optical centres into a common orientation whose x
//! axis is the baseline (left → right optical centre) and whose z axis is the mean of the two
//! optical axes made orthogonal to the baseline; the y axis completes a right-handed frame.
//! Rotations `R1`, `R2` map original left/right camera coordinates into that rectified frame:
//! `p_rect = R1 p_left`, and with `T_left_right = (R, t)`, `R2 = R1 R`. Both rectified cameras
//! share the intrinsics `K' = [f 0 cx; 0 f cy; 0 0 1]` (no distortion) with
//! `f = min(fx, fy)` over both cameras, and the right camera sits at `x = B` in the rectified frame:
//!
//! ```text
//! P1 = K' [I | 0],   P2 = K' [I | (-B, 0, 0)ᵀ]
//! Q  = [[1, 0, 0, -cx], [0, 1, 0, -cy], [0, 0, 0, f], [0, 0, 1/B, 0]],  (X Y Z W)ᵀ = Q (u v d 1)ᵀ
//! ```
//!
//! These rotations and matrices are computed by [`tubeloc_core::PairRectification`] (shared with
//! the ROS `camera_info` export of `tubeloc calib rig`). The remap tables send each rectified pixel through `R_i⁻¹` and the original camera model
//! (with its lens distortion) to a source pixel, sampled bilinearly. The valid region of each
//! rectified image is an axis-aligned rectangle inside which every pixel has a source inside the
//! original image.
//!
//! A rig whose right camera lies physically to the left of the "left" one still rectifies (the
//! rectified images are then rotated by 180°); rigs with (almost) zero baseline or a baseline
//! within 45° of the optical axis are refused, because their epipoles lie inside the image.

use crate::error::{Result, StereoError};
use crate::triangulate::{RectifiedGeometry, StereoPoint};
use nalgebra::{Matrix3, Point2, Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;
use tubeloc_core::{CameraModel, CoreError, PairRectification, Plane, Pose};

/// Source coordinates (pixels of the original image) of each rectified pixel; `NaN` where the
/// source lies outside the original image.
#[derive(Clone, Debug)]
pub struct RemapTable {
    /// Source x of each rectified pixel.
    pub map_x: Plane<f32>,
    /// Source y of each rectified pixel.
    pub map_y: Plane<f32>,
}

/// An axis-aligned pixel rectangle: top-left `(x, y)`, size `width x height`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct PixelRect {
    /// Left column.
    pub x: usize,
    /// Top row.
    pub y: usize,
    /// Width, pixels (0 when nothing is valid).
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
}

/// The rectification of a stereo pair: rotations, rectified camera, projection matrices, remap
/// tables and valid regions (see the module documentation for the formulas).
#[derive(Clone, Debug)]
pub struct StereoRectification {
    /// The rectifying rotations, the shared rectified camera and `P1`, `P2`, `Q`
    /// ([`PairRectification`], the same matrices the ROS export writes); its fields are read
    /// through this struct (`Deref`).
    pub pair: PairRectification,
    /// Remap table of the left image.
    pub map_left: RemapTable,
    /// Remap table of the right image.
    pub map_right: RemapTable,
    /// Valid rectangle of the rectified left image.
    pub valid_left: PixelRect,
    /// Valid rectangle of the rectified right image.
    pub valid_right: PixelRect,
    left: CameraModel,
    right: CameraModel,
}

impl std::ops::Deref for StereoRectification {
    type Target = PairRectification;

    fn deref(&self) -> &PairRectification {
        &self.pair
    }
}

impl StereoRectification {
    /// Rectifies the pair `left`, `right` with `t_left_right` (maps right-camera points into the
    /// left camera frame, metres). Errors on invalid or differently sized cameras, zero
    /// baseline and baselines within 45° of the optical axis.
    pub fn new(left: &CameraModel, right: &CameraModel, t_left_right: &Pose) -> Result<Self> {
        left.validate()?;
        right.validate()?;
        if left.width != right.width || left.height != right.height {
            return Err(StereoError::SizeMismatch { what: "left camera".into(), a_w: left.width as usize, a_h: left.height as usize, other: "right camera".into(), b_w: right.width as usize, b_h: right.height as usize });
        }
        let geom = PairRectification::new(left, right, t_left_right).map_err(|e| match e {
            CoreError::Invalid { message, .. } => StereoError::Unrectifiable(message),
            other => other.into(),
        })?;
        let map_left = remap_table(left, &geom.r_left, &geom.rectified);
        let map_right = remap_table(right, &geom.r_right, &geom.rectified);
        let valid_left = valid_rect(&map_left);
        let valid_right = valid_rect(&map_right);
        Ok(StereoRectification { pair: geom, map_left, map_right, valid_left, valid_right, left: left.clone(), right: right.clone() })
    }

    /// Focal length, principal point and baseline for [`crate::triangulate::triangulate`].
    pub fn geometry(&self) -> RectifiedGeometry {
        RectifiedGeometry { f: self.rectified.fx, cx: self.rectified.cx, cy: self.rectified.cy, baseline: self.baseline }
    }

    /// Remaps an original image pair into rectified images (bilinear, 0 outside the source).
    /// Errors when an image does not have its camera's size.
    pub fn rectify_pair(&self, left: &Plane<u8>, right: &Plane<u8>) -> Result<(Plane<u8>, Plane<u8>)> {
        for (name, img, cam) in [("left image", left, &self.left), ("right image", right, &self.right)] {
            if img.width != cam.width as usize || img.height != cam.height as usize {
                return Err(StereoError::SizeMismatch { what: name.into(), a_w: img.width, a_h: img.height, other: format!("its camera model ({})", name.split(' ').next().unwrap_or("")), b_w: cam.width as usize, b_h: cam.height as usize });
            }
        }
        Ok((remap(left, &self.map_left), remap(right, &self.map_right)))
    }

    /// Maps a point of the rectified left frame into the original left camera frame (`R1ᵀ p`).
    pub fn to_left_camera(&self, p: &Point3<f64>) -> Point3<f64> {
        Point3::from(self.r_left.transpose() * p.coords)
    }

    /// Rectified left pixel of a point given in the original left camera frame.
    pub fn project_left(&self, p_left: &Point3<f64>) -> Option<Point2<f64>> {
        self.rectified.project(&Point3::from(self.r_left * p_left.coords))
    }

    /// Triangulated points converted into the original left camera frame (`σ_Z` stays the
    /// depth uncertainty along the rectified optical axis).
    pub fn points_in_left_camera(&self, pts: &[StereoPoint]) -> Vec<StereoPoint> {
        pts.iter().map(|p| StereoPoint { point: self.to_left_camera(&p.point), ..*p }).collect()
    }
}

fn remap_table(cam: &CameraModel, rot: &Matrix3<f64>, rect: &CameraModel) -> RemapTable {
    let (w, h) = (rect.width as usize, rect.height as usize);
    let rt = rot.transpose();
    let mut map_x = Plane::<f32>::new(w, h);
    let mut map_y = Plane::<f32>::new(w, h);
    let (sw, sh) = (cam.width as f64 - 1.0, cam.height as f64 - 1.0);
    map_x.data.par_chunks_mut(w).zip(map_y.data.par_chunks_mut(w)).enumerate().for_each(|(v, (mx, my))| {
        for u in 0..w {
            let ray = rt * Vector3::new((u as f64 - rect.cx) / rect.fx, (v as f64 - rect.cy) / rect.fy, 1.0);
            let src = if ray.z > 1e-9 { Some(cam.project_normalized(ray.x / ray.z, ray.y / ray.z)) } else { None };
            match src {
                Some(s) if s.x >= 0.0 && s.y >= 0.0 && s.x <= sw && s.y <= sh => {
                    mx[u] = s.x as f32;
                    my[u] = s.y as f32;
                }
                _ => {
                    mx[u] = f32::NAN;
                    my[u] = f32::NAN;
                }
            }
        }
    });
    RemapTable { map_x, map_y }
}

/// Bilinear remap of `img` through `table`; pixels without a source are 0.
pub fn remap(img: &Plane<u8>, table: &RemapTable) -> Plane<u8> {
    let (w, h) = (table.map_x.width, table.map_x.height);
    let mut out = Plane::<u8>::new(w, h);
    out.data.par_chunks_mut(w).enumerate().for_each(|(v, orow)| {
        for (u, o) in orow.iter_mut().enumerate() {
            let (x, y) = (table.map_x.get(u, v), table.map_y.get(u, v));
            if x.is_nan() {
                continue;
            }
            let (x0, y0) = (x.floor() as usize, y.floor() as usize);
            let (x1, y1) = ((x0 + 1).min(img.width - 1), (y0 + 1).min(img.height - 1));
            let (fx, fy) = (x - x0 as f32, y - y0 as f32);
            let a = img.get(x0, y0) as f32 * (1.0 - fx) + img.get(x1, y0) as f32 * fx;
            let b = img.get(x0, y1) as f32 * (1.0 - fx) + img.get(x1, y1) as f32 * fx;
            *o = (a * (1.0 - fy) + b * fy).round().clamp(0.0, 255.0) as u8;
        }
    });
    out
}

/// A large axis-aligned rectangle of valid pixels: the bounding box of the valid pixels, shrunk
/// one side at a time (the side with the most invalid pixels) until all its border pixels are valid.
fn valid_rect(table: &RemapTable) -> PixelRect {
    let (w, h) = (table.map_x.width, table.map_x.height);
    let ok = |x: usize, y: usize| !table.map_x.get(x, y).is_nan();
    let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0usize, 0usize);
    for y in 0..h {
        for x in 0..w {
            if ok(x, y) {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x + 1);
                y1 = y1.max(y + 1);
            }
        }
    }
    while x0 < x1 && y0 < y1 {
        let bad_row = |y: usize| (x0..x1).filter(|&x| !ok(x, y)).count();
        let bad_col = |x: usize| (y0..y1).filter(|&y| !ok(x, y)).count();
        let sides = [bad_row(y0), bad_row(y1 - 1), bad_col(x0), bad_col(x1 - 1)];
        let (worst, &n) = sides.iter().enumerate().max_by_key(|(_, &n)| n).unwrap_or((0, &0));
        if n == 0 {
            return PixelRect { x: x0, y: y0, width: x1 - x0, height: y1 - y0 };
        }
        match worst {
            0 => y0 += 1,
            1 => y1 -= 1,
            2 => x0 += 1,
            _ => x1 -= 1,
        }
    }
    PixelRect { x: 0, y: 0, width: 0, height: 0 }
}
