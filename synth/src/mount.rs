//! The tag mount of with-tags scenes: two tag36h11 plates rigidly tied to one tube.
//!
//! As in the paper, the mount sits a short distance from the tube and its arm is buried under
//! sand so the tube looks isolated; only the two tag plates show above small sand piles.
//! The tag transforms `T_tube_tag` come from `data/tag_mount.toml` (embedded at build time).
//! Tag frame (AprilTag convention): origin at the tag centre on the printed face, x to the
//! right and y down as printed, z into the plate. Corners are listed in the detector's
//! order: `(−s/2, +s/2), (+s/2, +s/2), (+s/2, −s/2), (−s/2, −s/2)` (tag frame, `s` = edge of
//! the black border square).

use crate::heightfield::HeightField;
use crate::objects::PlateObject;
use crate::scene::sand;
use crate::tags::{TagFamily, TagTexture};
use crate::terrain::{srgb_to_linear, SAND_SRGB};
use crate::SynthError;
use nalgebra::{Matrix3, Point3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};
use tubeloc_core::Pose;

/// The mount description shipped in `data/tag_mount.toml` (tag ids, sizes, `T_tube_tag`).
pub const TAG_MOUNT_TOML: &str = include_str!("../../data/tag_mount.toml");

#[derive(Deserialize)]
struct MountFile {
    family: TagFamily,
    tags: Vec<MountFileTag>,
}

#[derive(Deserialize)]
struct MountFileTag {
    id: u32,
    size_m: f64,
    rotation: [[f64; 3]; 3],
    translation_m: [f64; 3],
}

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
    /// True when a disc of radius `rad` at `(x, y)` stays clear of the plates.
    pub fn clear_of(&self, x: f64, y: f64, rad: f64) -> bool {
        self.plates.iter().all(|p| {
            let c = p.t_world_box.translation();
            ((c.x - x).powi(2) + (c.y - y).powi(2)).sqrt() > rad + p.half.x.max(p.half.y) * 1.5
        })
    }
}

/// One tag of a mount description, relative to its tube: `(id, size_m, T_tube_tag)` (edge of the
/// black border square in metres; pose of the tag frame in the tube frame).
pub type TubeMountTag = (u32, f64, Pose);

/// Parses a mount description (TOML text, see `data/tag_mount.toml`) into `(family, [(id,
/// size_m, T_tube_tag)])`.
pub fn parse_mount(text: &str) -> Result<(TagFamily, Vec<TubeMountTag>), SynthError> {
    let f: MountFile = toml::from_str(text).map_err(|e| SynthError::Invalid(format!("tag mount description: {e}")))?;
    let mut out = Vec::new();
    for t in f.tags {
        let r = Matrix3::from_fn(|i, k| t.rotation[i][k]);
        let pose = Pose::try_from_matrix(&r, Vector3::from(t.translation_m))?;
        if !(t.size_m.is_finite() && t.size_m > 0.0) {
            return Err(SynthError::Invalid(format!("tag {}: size_m must be positive", t.id)));
        }
        out.push((t.id, t.size_m, pose));
    }
    Ok((f.family, out))
}

/// `T_world_tube` rotation for the tube that carries the mount: axis along `axis` (horizontal),
/// tube +y pointing down, as `data/tag_mount.toml` assumes.
pub fn carrier_rotation(axis: &Vector3<f64>) -> Rotation3<f64> {
    let z = axis.normalize();
    let y = -Vector3::z();
    let x = y.cross(&z);
    Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]))
}

/// Builds the mount of tube `tube_index` (pose `t_world_tube`) from the shipped description.
/// Each tag lies on a 3 mm plate whose box frame is the tag frame shifted half a thickness
/// into the plate (box −z face = printed face).
pub fn build_mount(t_world_tube: &Pose, tube_index: usize) -> Result<TagMount, SynthError> {
    let (family, list) = parse_mount(TAG_MOUNT_TOML)?;
    let mut tags = Vec::new();
    let mut plates = Vec::new();
    for (id, size, t_tube_tag) in list {
        let tex = TagTexture::new(family, id, size).ok_or_else(|| SynthError::Invalid(format!("{} has no id {id}", family.name())))?;
        let t_world_tag = *t_world_tube * t_tube_tag;
        let half = Vector3::new(tex.half_extent() + 0.006, tex.half_extent() + 0.006, 0.0015);
        let t_world_box = t_world_tag * Pose::from_parts(Rotation3::identity(), Vector3::new(0.0, 0.0, half.z));
        let s = size / 2.0;
        let corners_world = [(-s, s), (s, s), (s, -s), (-s, -s)].map(|(u, v)| {
            let p = t_world_tag.transform_point(&Point3::new(u, v, 0.0));
            [p.x, p.y, p.z]
        });
        tags.push(MountTag { id, size_m: size, t_world_tag, t_tube_tag, corners_world });
        plates.push(PlateObject { t_world_box, half, albedo: [0.70, 0.70, 0.68], tag: Some(tex) });
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
