//! The tag mount of with-tags scenes: two tag36h11 plates rigidly tied to one tube.
//!
//! As in the paper, the mount sits a short distance from the tube and its arm is buried under
//! sand so the tube looks isolated; only the two tag plates show above small sand piles.
//! Tag frame (AprilTag convention): origin at the tag centre on the plate's top face, x to the
//! right and y down in the tag image, z into the plate. Corners are listed in the detector's
//! order: `(−s/2, +s/2), (+s/2, +s/2), (+s/2, −s/2), (−s/2, −s/2)` (tag frame, `s` = edge of
//! the black border square), i.e. counter-clockwise in the image.

use crate::heightfield::HeightField;
use crate::objects::PlateObject;
use crate::scene::sand;
use crate::terrain::{srgb_to_linear, SAND_SRGB};
use crate::SynthError;
use nalgebra::{Matrix3, Point3, Rotation3, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};
use tubeloc_core::Pose;

/// Tag ids carried by the mount.
pub const MOUNT_TAG_IDS: [u32; 2] = [0, 1];
/// Size of one tag cell (module), metres.
pub const TAG_CELL_M: f64 = 0.008;

/// One tag of the mount.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MountTag {
    /// tag36h11 id.
    pub id: u32,
    /// Edge of the black border square, metres.
    pub size_m: f64,
    /// Pose of the tag frame in the world.
    #[serde(rename = "T_world_tag")]
    pub t_world_tag: Pose,
    /// Pose of the tag frame in the tube frame (the mount's rigid transform).
    #[serde(rename = "T_tube_tag")]
    pub t_tube_tag: Pose,
    /// Corners of the black border square in the world, detector order.
    pub corners_world: [[f64; 3]; 4],
}

/// The mount: which tube carries it and its tags and plates.
#[derive(Clone, Debug)]
pub struct TagMount {
    /// Index of the carrying tube.
    pub tube_index: usize,
    /// The tags.
    pub tags: Vec<MountTag>,
    /// Plates to ray-cast (one per tag).
    pub plates: Vec<PlateObject>,
}

impl TagMount {
    /// True when a disc of radius `rad` at `(x, y)` stays clear of the plates and the arm.
    pub fn clear_of(&self, x: f64, y: f64, rad: f64) -> bool {
        self.plates.iter().all(|p| {
            let c = p.t_world_box.translation();
            ((c.x - x).powi(2) + (c.y - y).powi(2)).sqrt() > rad + p.half.x.max(p.half.y) * 1.5
        })
    }
}

/// Tag bit image of `id`: `(cells, bits)` with `bits[row * cells + col]` true for white,
/// including the white outer border; `None` while the tag36h11 table (`crate::tags`, owned by
/// the calibration work) is not wired in, in which case the plates are drawn blank.
fn tag_image(_id: u32) -> Option<(usize, Vec<bool>)> {
    None
}

/// Builds the mount beside tube `tube_index` (pose `t_world_tube`, radius `r`).
pub fn build_mount<R: Rng>(rng: &mut R, t_world_tube: &Pose, tube_index: usize, r: f64) -> Result<TagMount, SynthError> {
    let centre = t_world_tube.translation();
    let axis = t_world_tube.transform_vector(&Vector3::z());
    let perp = Vector3::new(-axis.y, axis.x, 0.0).normalize();
    let side = if rng.random::<bool>() { 1.0 } else { -1.0 };
    let ground = centre.z - r;
    let mut tags = Vec::new();
    let mut plates = Vec::new();
    for (k, &id) in MOUNT_TAG_IDS.iter().enumerate() {
        let (cells, bits) = match tag_image(id) {
            Some(t) => t,
            None => (10, vec![true; 100]),
        };
        let total = cells as f64 * TAG_CELL_M;
        let black = (cells as f64 - 2.0) * TAG_CELL_M;
        let along = if k == 0 { -0.075 } else { 0.075 };
        let c = centre + perp * (side * 0.20) + axis * along;
        let z = ground + 0.035 + rng.random_range(0.0..0.01);
        // Plate frame: z up (tilted a little toward the tube side), x along the tube axis.
        let tilt = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), side * rng.random_range(0.1..0.3));
        let x = tilt * axis;
        let zb = tilt * Vector3::z();
        let y = zb.cross(&x);
        let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, zb]));
        let half = Vector3::new(total / 2.0 + 0.006, total / 2.0 + 0.006, 0.003);
        let t_world_box = Pose::from_parts(rot, Vector3::new(c.x, c.y, z));
        // Tag frame in the plate frame: x = +x, y = −y, z = −z, origin on the top face.
        let r_box_tag = Rotation3::from_matrix_unchecked(Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0));
        let t_box_tag = Pose::from_parts(r_box_tag, Vector3::new(0.0, 0.0, half.z));
        let t_world_tag = t_world_box * t_box_tag;
        let s = black / 2.0;
        let corners_world = [(-s, s), (s, s), (s, -s), (-s, -s)].map(|(u, v)| {
            let p = t_world_tag.transform_point(&Point3::new(u, v, 0.0));
            [p.x, p.y, p.z]
        });
        tags.push(MountTag { id, size_m: black, t_world_tag, t_tube_tag: t_world_tube.inverse() * t_world_tag, corners_world });
        plates.push(PlateObject { t_world_box, half, albedo: [0.7, 0.7, 0.68], tag: Some((cells, bits, total / 2.0)) });
    }
    Ok(TagMount { tube_index, tags, plates })
}

/// Piles sand under the plates and over the buried arm (between tube and plates), labelling
/// the vertices [`sand::MOUNT_COVER`].
pub fn cover_with_sand(m: &TagMount, hf: &mut HeightField, labels: &mut [u8], lin: &mut [[f32; 3]], t_world_tube: &Pose, r: f64) {
    let sand_lin = srgb_to_linear(SAND_SRGB);
    let tube_c = t_world_tube.translation();
    let ground = tube_c.z - r;
    let n = hf.nx;
    for p in &m.plates {
        let c = p.t_world_box.translation();
        let bottom = c.z - 0.012;
        let reach = 0.12;
        let (i0, i1) = (((c.x - reach - hf.x0) / hf.cell).floor().max(0.0) as usize, (((c.x + reach - hf.x0) / hf.cell).ceil() as usize).min(n - 1));
        let (j0, j1) = (((c.y - reach - hf.y0) / hf.cell).floor().max(0.0) as usize, (((c.y + reach - hf.y0) / hf.cell).ceil() as usize).min(hf.ny - 1));
        // Arm: segment from near the tube to the plate, buried under a low berm.
        let dir = Vector3::new(c.x - tube_c.x, c.y - tube_c.y, 0.0);
        let len = dir.norm();
        let dir = dir / len.max(1e-9);
        for j in j0..=j1 {
            for i in i0..=i1 {
                let (x, y) = (hf.x0 + i as f64 * hf.cell, hf.y0 + j as f64 * hf.cell);
                let d = ((x - c.x).powi(2) + (y - c.y).powi(2)).sqrt();
                let pile = bottom - (d - 0.03).max(0.0) * 0.6;
                let v = Vector3::new(x - tube_c.x, y - tube_c.y, 0.0);
                let s = v.dot(&dir);
                let q = (v - dir * s).norm();
                let berm = if s > r + 0.03 && s < len && q < 0.03 { ground + 0.008 * (1.0 - q / 0.03) } else { f64::MIN };
                let target = pile.max(berm);
                let idx = j * n + i;
                if target > hf.h[idx] as f64 + 0.001 {
                    hf.h[idx] = target as f32;
                    labels[idx] = sand::MOUNT_COVER;
                    lin[idx] = sand_lin;
                }
            }
        }
    }
}
