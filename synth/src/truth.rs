//! Exact per-tube ground truth of a rendered image: visible mask, amodal (unoccluded) area,
//! visible fraction, occlusion kind, bounding box and pose.
//!
//! The visible mask of tube `i` is the set of pixels whose primary ray hits tube `i` first
//! (the renderer's instance plane). The amodal mask is the set of pixels, inside or outside
//! the image, whose ray meets tube `i` when everything else is removed; it is cast over the
//! projection of the tube's bounding box, without clipping to the image. Then
//! `visible_fraction = visible area / amodal area`, and the occlusion kind is the surface
//! that hides most of the hidden part (`"border"` for the part outside the image), or
//! `"none"` when less than 3 % is hidden.

use crate::objects::Objects;
use crate::render::{pixel_ray, RenderOutput, SurfaceKind};
use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use tubeloc_core::{BinaryMask, CameraModel, Pose};

/// What hides a tube.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Occlusion {
    /// Less than 3 % of the tube is hidden.
    None,
    /// A rock.
    Rock,
    /// A sand mound over the tube.
    SandMound,
    /// A dune along the tube.
    Dune,
    /// The image border (part of the tube lies outside the image).
    Border,
    /// Other terrain (ditch walls, slabs, mount sand).
    Terrain,
    /// Another tube.
    Tube,
    /// The tag mount.
    Mount,
}

impl Occlusion {
    /// Name as written in annotations.
    pub fn name(&self) -> &'static str {
        match self {
            Occlusion::None => "none",
            Occlusion::Rock => "rock",
            Occlusion::SandMound => "sand_mound",
            Occlusion::Dune => "dune",
            Occlusion::Border => "border",
            Occlusion::Terrain => "terrain",
            Occlusion::Tube => "tube",
            Occlusion::Mount => "mount",
        }
    }
}

/// Ground truth of one tube in one image.
#[derive(Clone, Debug)]
pub struct TubeTruth {
    /// Index of the tube in the scene.
    pub tube: usize,
    /// Visible mask, image size.
    pub visible: BinaryMask,
    /// Visible area, pixels.
    pub visible_area: u64,
    /// Amodal area (inside and outside the image), pixels.
    pub amodal_area: u64,
    /// `visible_area / amodal_area`.
    pub visible_fraction: f64,
    /// Dominant occluder.
    pub occlusion: Occlusion,
    /// Visible-mask box `[x, y, w, h]` (COCO convention, pixel edges).
    pub bbox: [f64; 4],
    /// Amodal box `[x, y, w, h]`, may extend outside the image.
    pub amodal_bbox: [f64; 4],
    /// Pose of the tube in the camera frame.
    pub t_cam_tube: Pose,
}

/// Pixel rectangle `(u0, v0, u1, v1)` (inclusive, may lie outside the image) covering the
/// projection of tube `i`'s bounding box, or `None` when part of it is behind the camera.
pub fn projected_rect(objects: &Objects, i: usize, cam: &CameraModel, t_world_cam: &Pose) -> Option<(i64, i64, i64, i64)> {
    let tube = &objects.tubes[i];
    let (hl, r) = tube.shape.bounds();
    let t_cam_tube = t_world_cam.inverse() * tube.t_world_tube;
    let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                let p = t_cam_tube.transform_point(&Point3::new(sx * r, sy * r, sz * hl));
                if p.z < 0.05 {
                    return None;
                }
                let px = cam.project(&p)?;
                u0 = u0.min(px.x);
                v0 = v0.min(px.y);
                u1 = u1.max(px.x);
                v1 = v1.max(px.y);
            }
        }
    }
    Some((u0.floor() as i64 - 1, v0.floor() as i64 - 1, u1.ceil() as i64 + 1, v1.ceil() as i64 + 1))
}

/// Ground truth of every tube that is at least partly visible in `out`.
pub fn tube_truth(objects: &Objects, cam: &CameraModel, t_world_cam: &Pose, out: &RenderOutput) -> Vec<TubeTruth> {
    let (w, h) = (out.width as i64, out.height as i64);
    let mut result = Vec::new();
    for i in 0..objects.tubes.len() {
        let Some((u0, v0, u1, v1)) = projected_rect(objects, i, cam, t_world_cam) else { continue };
        if u1 < 0 || v1 < 0 || u0 >= w || v0 >= h {
            continue;
        }
        let id = (i + 1) as u16;
        let mut counts = [0u64; 8];
        let (mut amodal, mut border) = (0u64, 0u64);
        let (mut ax0, mut ay0, mut ax1, mut ay1) = (i64::MAX, i64::MAX, i64::MIN, i64::MIN);
        let mut visible = BinaryMask::new(out.width, out.height);
        let mut vis_area = 0u64;
        for v in v0..=v1 {
            for u in u0..=u1 {
                let inside = u >= 0 && v >= 0 && u < w && v < h;
                let idx = if inside { (v * w + u) as usize } else { 0 };
                if inside && out.instance.data[idx] == id {
                    amodal += 1;
                    vis_area += 1;
                    visible.data[idx] = 1;
                } else {
                    let (ray, _) = pixel_ray(cam, t_world_cam, u as f64, v as f64);
                    if objects.intersect_tube(i, &ray, 0.0, 1e3).is_none() {
                        continue;
                    }
                    amodal += 1;
                    if inside {
                        let k = out.surface.data[idx] as usize;
                        let kind = if out.instance.data[idx] != 0 { SurfaceKind::Tube as usize } else { k };
                        counts[kind.min(7)] += 1;
                    } else {
                        border += 1;
                    }
                }
                ax0 = ax0.min(u);
                ay0 = ay0.min(v);
                ax1 = ax1.max(u);
                ay1 = ay1.max(v);
            }
        }
        if vis_area == 0 || amodal == 0 {
            continue;
        }
        let hidden = amodal - vis_area;
        let occlusion = if (hidden as f64) < 0.03 * amodal as f64 {
            Occlusion::None
        } else {
            let cands = [
                (border, Occlusion::Border),
                (counts[SurfaceKind::Rock as usize], Occlusion::Rock),
                (counts[SurfaceKind::SandMound as usize], Occlusion::SandMound),
                (counts[SurfaceKind::Dune as usize], Occlusion::Dune),
                (counts[SurfaceKind::Ground as usize] + counts[SurfaceKind::MountSand as usize], Occlusion::Terrain),
                (counts[SurfaceKind::Tube as usize], Occlusion::Tube),
                (counts[SurfaceKind::Plate as usize], Occlusion::Mount),
            ];
            cands.iter().max_by_key(|c| c.0).map(|c| c.1).unwrap_or(Occlusion::None)
        };
        result.push(TubeTruth {
            tube: i,
            bbox: visible.bbox(),
            visible,
            visible_area: vis_area,
            amodal_area: amodal,
            visible_fraction: vis_area as f64 / amodal as f64,
            occlusion,
            amodal_bbox: [ax0 as f64, ay0 as f64, (ax1 - ax0 + 1) as f64, (ay1 - ay0 + 1) as f64],
            t_cam_tube: t_world_cam.inverse() * objects.tubes[i].t_world_tube,
        });
    }
    result
}
