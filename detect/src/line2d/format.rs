//! The template library file (`.tlt`): versioned, length-checked, checksummed binary.
//!
//! Layout (little endian):
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `TUBELT2D` |
//! | 4 | format version `u32` ([`FORMAT_VERSION`]) |
//! | 8 | payload length `u64` |
//! | 4 | CRC-32 (IEEE, `crc32fast`) of the payload |
//! | n | payload |
//!
//! Payload: camera `fx fy cx cy` (f64), view parameters `step inplane_step inplane_range
//! dedupe_tol dist_min dist_max dist_step` (f64), features per level (u32), template count
//! (u32), then per template: id (u32), alpha, psi, distance (f32), rotation 3x3 row-major and
//! translation (f64), centre (2 f32), level count (u8), per level width, height (u16), feature
//! count (u32) and features `x y` (u16) `ori` (u8); finally the level-0 mask, 1 bit per pixel,
//! row-major, LSB first.

use crate::line2d::render::Pinhole;
use crate::line2d::template::{Feature, LibraryParams, Template, TemplateLevel, TemplateLibrary};
use crate::line2d::viewpoints::ViewParams;
use crate::line2d::{Line2dError, N_ORI};
use nalgebra::{Matrix3, Vector3};
use std::path::Path;
use tubeloc_core::Pose;

/// File magic.
pub const MAGIC: &[u8; 8] = b"TUBELT2D";
/// Current format version; files of other versions are refused.
pub const FORMAT_VERSION: u32 = 1;
const HEADER: usize = 8 + 4 + 8 + 4;

struct W(Vec<u8>);
impl W {
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u16(&mut self, v: u16) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
}

struct R<'a> {
    b: &'a [u8],
    pos: usize,
}
impl<'a> R<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        if self.b.len() - self.pos < n {
            return Err(format!("payload truncated at byte {}", self.pos));
        }
        let s = &self.b[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.take(8)?.try_into().unwrap_or([0; 8])))
    }
    fn f32(&mut self) -> Result<f32, String> {
        Ok(f32::from_le_bytes(self.take(4)?.try_into().unwrap_or([0; 4])))
    }
    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap_or([0; 4])))
    }
    fn u16(&mut self) -> Result<u16, String> {
        Ok(u16::from_le_bytes(self.take(2)?.try_into().unwrap_or([0; 2])))
    }
    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
}

impl TemplateLibrary {
    /// Serializes the library to bytes (header + payload).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = W(Vec::new());
        let p = &self.params;
        for v in [p.camera.fx, p.camera.fy, p.camera.cx, p.camera.cy] {
            w.f64(v);
        }
        let v = &p.views;
        for x in [v.step_deg, v.inplane_step_deg, v.inplane_range_deg, v.dedupe_tol_deg, v.dist_min, v.dist_max, v.dist_step] {
            w.f64(x);
        }
        w.u32(p.features);
        w.u32(self.templates.len() as u32);
        for t in &self.templates {
            w.u32(t.id);
            w.f32(t.alpha_deg);
            w.f32(t.psi_deg);
            w.f32(t.distance);
            let r = t.t_cam_tube.rotation();
            for i in 0..3 {
                for k in 0..3 {
                    w.f64(r[(i, k)]);
                }
            }
            let tr = t.t_cam_tube.translation();
            for i in 0..3 {
                w.f64(tr[i]);
            }
            w.f32(t.centre[0]);
            w.f32(t.centre[1]);
            w.0.push(t.levels.len() as u8);
            for l in &t.levels {
                w.u16(l.width);
                w.u16(l.height);
                w.u32(l.features.len() as u32);
                for f in &l.features {
                    w.u16(f.x);
                    w.u16(f.y);
                    w.0.push(f.ori);
                }
            }
            let mut bits = vec![0u8; t.mask.len().div_ceil(8)];
            for (i, &m) in t.mask.iter().enumerate() {
                if m != 0 {
                    bits[i / 8] |= 1 << (i % 8);
                }
            }
            w.0.extend_from_slice(&bits);
        }
        let payload = w.0;
        let mut out = Vec::with_capacity(HEADER + payload.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        out.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
        out.extend_from_slice(&payload);
        out
    }

    /// Writes the library atomically to `path`.
    pub fn save(&self, path: &Path) -> Result<(), Line2dError> {
        Ok(tubeloc_core::files::write_atomic(path, &self.to_bytes())?)
    }

    /// Reads a library file; refuses wrong magic, version, length or checksum, and invalid
    /// content, with an error naming the file.
    pub fn load(path: &Path) -> Result<TemplateLibrary, Line2dError> {
        let bytes = std::fs::read(path).map_err(|e| Line2dError::Io { path: path.into(), error: e })?;
        Self::from_bytes(&bytes).map_err(|message| Line2dError::Format { path: path.into(), message })
    }

    /// Parses library bytes; the error text says what is wrong.
    pub fn from_bytes(bytes: &[u8]) -> Result<TemplateLibrary, String> {
        if bytes.len() < HEADER {
            return Err(format!("not a tubeloc template library: {} bytes, shorter than the {HEADER}-byte header", bytes.len()));
        }
        if &bytes[0..8] != MAGIC {
            return Err("not a tubeloc template library (bad magic)".into());
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().unwrap_or([0; 4]));
        if version != FORMAT_VERSION {
            return Err(format!("template library format version {version}, this program reads version {FORMAT_VERSION}: rebuild it with `tubeloc templates build`"));
        }
        let len = u64::from_le_bytes(bytes[12..20].try_into().unwrap_or([0; 8]));
        let crc = u32::from_le_bytes(bytes[20..24].try_into().unwrap_or([0; 4]));
        let payload = &bytes[HEADER..];
        if payload.len() as u64 != len {
            return Err(format!("length mismatch: header says {len} payload bytes, file has {} (truncated or padded)", payload.len()));
        }
        let got = crc32fast::hash(payload);
        if got != crc {
            return Err(format!("checksum mismatch (stored {crc:08x}, computed {got:08x}): the file is corrupt"));
        }
        parse_payload(payload)
    }
}

fn parse_payload(payload: &[u8]) -> Result<TemplateLibrary, String> {
    let mut r = R { b: payload, pos: 0 };
    let camera = Pinhole { fx: r.f64()?, fy: r.f64()?, cx: r.f64()?, cy: r.f64()? };
    let views = ViewParams { step_deg: r.f64()?, inplane_step_deg: r.f64()?, inplane_range_deg: r.f64()?, dedupe_tol_deg: r.f64()?, dist_min: r.f64()?, dist_max: r.f64()?, dist_step: r.f64()? };
    let features = r.u32()?;
    let n = r.u32()? as usize;
    let mut templates = Vec::with_capacity(n.min(1 << 20));
    for i in 0..n {
        let id = r.u32()?;
        if id as usize != i {
            return Err(format!("template {i} has id {id}"));
        }
        let (alpha_deg, psi_deg, distance) = (r.f32()?, r.f32()?, r.f32()?);
        let mut m = Matrix3::zeros();
        for a in 0..3 {
            for b in 0..3 {
                m[(a, b)] = r.f64()?;
            }
        }
        let t = Vector3::new(r.f64()?, r.f64()?, r.f64()?);
        let t_cam_tube = Pose::try_from_matrix(&m, t).map_err(|e| format!("template {i}: {e}"))?;
        let centre = [r.f32()?, r.f32()?];
        let nl = r.u8()? as usize;
        if nl != 2 {
            return Err(format!("template {i}: {nl} pyramid levels, expected 2"));
        }
        let mut levels = Vec::with_capacity(nl);
        for _ in 0..nl {
            let (width, height) = (r.u16()?, r.u16()?);
            let nf = r.u32()? as usize;
            let mut feats = Vec::with_capacity(nf.min(1 << 16));
            for _ in 0..nf {
                let f = Feature { x: r.u16()?, y: r.u16()?, ori: r.u8()? };
                if f.x >= width || f.y >= height || f.ori as usize >= N_ORI {
                    return Err(format!("template {i}: feature ({}, {}, {}) outside {width}x{height} or bad orientation", f.x, f.y, f.ori));
                }
                feats.push(f);
            }
            if feats.is_empty() {
                return Err(format!("template {i}: a level without features"));
            }
            levels.push(TemplateLevel { width, height, features: feats });
        }
        let npx = levels[0].width as usize * levels[0].height as usize;
        let bits = r.take(npx.div_ceil(8))?;
        let mask: Vec<u8> = (0..npx).map(|k| (bits[k / 8] >> (k % 8)) & 1).collect();
        let area = mask.iter().map(|&m| m as u32).sum();
        templates.push(Template { id, alpha_deg, psi_deg, distance, t_cam_tube, centre, levels, mask, area });
    }
    if r.pos != payload.len() {
        return Err(format!("{} trailing bytes after the last template", payload.len() - r.pos));
    }
    Ok(TemplateLibrary { params: LibraryParams { camera, views, features }, templates })
}
