//! The tube as coaxial cylinders, for contour generation and ray-cast visibility.
//!
//! Each section of [`TubeModel`] becomes a finite cylinder `{z0 <= z <= z1, ρ <= r}` in the tube
//! frame (origin at the tube centre, +z toward the seal end, metres). Visibility of contour
//! points is decided by exact segment-versus-cylinder tests ([`CylinderModel::occludes`]).

use crate::error::RefineError;
use nalgebra::{Point3, Vector3};
use tubeloc_core::TubeModel;

/// One coaxial section in the tube frame (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Section {
    /// Lower end along the axis (toward the foot).
    pub z0: f64,
    /// Upper end along the axis (toward the seal end).
    pub z1: f64,
    /// Radius.
    pub r: f64,
}

/// The tube's cylinder stack.
#[derive(Clone, Debug, PartialEq)]
pub struct CylinderModel {
    /// Sections ordered from foot (most negative z) to seal end.
    pub sections: Vec<Section>,
    /// Total length, metres.
    pub length: f64,
}

impl CylinderModel {
    /// Builds the model from the parametric tube (sections sorted by `z0`, tube-frame z).
    pub fn new(tube: &TubeModel) -> Result<Self, RefineError> {
        tube.validate()?;
        let mut sections: Vec<Section> = tube
            .sections
            .iter()
            .map(|s| {
                let (z0, z1) = tube.section_z_in_tube_frame(s);
                Section { z0, z1, r: s.radius }
            })
            .collect();
        sections.sort_by(|a, b| a.z0.total_cmp(&b.z0));
        Self::from_sections(sections)
    }

    /// A single plain cylinder of the given length and radius, centred (metres).
    pub fn plain(length: f64, radius: f64) -> Result<Self, RefineError> {
        Self::from_sections(vec![Section { z0: -length / 2.0, z1: length / 2.0, r: radius }])
    }

    fn from_sections(sections: Vec<Section>) -> Result<Self, RefineError> {
        if sections.is_empty() {
            return Err(RefineError::Model("no sections".into()));
        }
        if sections.iter().any(|s| !(s.r > 0.0 && s.z1 > s.z0 && s.r.is_finite() && s.z0.is_finite() && s.z1.is_finite())) {
            return Err(RefineError::Model("sections need z0 < z1 and a positive radius".into()));
        }
        let zmin = sections.iter().map(|s| s.z0).fold(f64::INFINITY, f64::min);
        let zmax = sections.iter().map(|s| s.z1).fold(f64::NEG_INFINITY, f64::max);
        Ok(CylinderModel { sections, length: zmax - zmin })
    }

    /// Largest radius, metres.
    pub fn max_radius(&self) -> f64 {
        self.sections.iter().map(|s| s.r).fold(0.0, f64::max)
    }

    /// Scene occlusion margin, metres: a scene depth (stereo) more than this in front of a
    /// point of the tube's surface hides it (`4 mm + r_max / 2`: stereo noise plus the
    /// surface's own depth change within a pixel of a limb).
    pub fn occlusion_margin(&self) -> f64 {
        0.004 + 0.5 * self.max_radius()
    }

    /// Radius of the longest section (the body), metres.
    pub fn body_radius(&self) -> f64 {
        self.sections.iter().max_by(|a, b| (a.z1 - a.z0).total_cmp(&(b.z1 - b.z0))).map(|s| s.r).unwrap_or(0.0)
    }

    /// Radius at axial coordinate `z` of the tube frame (largest section covering `z`), or 0.
    pub fn radius_at(&self, z: f64) -> f64 {
        self.sections.iter().filter(|s| z >= s.z0 && z <= s.z1).map(|s| s.r).fold(0.0, f64::max)
    }

    /// Radius of the neighbour beyond end `end` (-1: below `z0`, +1: above `z1`) of section `i`;
    /// 0 when that end is a free end of the tube.
    pub fn neighbour_radius(&self, i: usize, end: i8) -> f64 {
        let s = self.sections[i];
        let (z, eps) = if end < 0 { (s.z0, -1e-7) } else { (s.z1, 1e-7) };
        self.sections.iter().enumerate().filter(|(k, o)| *k != i && z + eps >= o.z0 && z + eps <= o.z1).map(|(_, o)| o.r).fold(0.0, f64::max)
    }

    /// True when the segment from the camera centre (origin) to `p` (camera frame, metres)
    /// passes through the solid tube (centre `c`, unit axis `a` toward the seal end) before
    /// reaching `p`: `p` is self-occluded. `p` should be pushed slightly off the surface
    /// (outward) by the caller.
    ///
    /// Exact: for each section the segment parameters `s ∈ [0, 1)` with
    /// `|w⊥ + s d⊥|² < r²` (a quadratic) and `z0 < w·a + s d·a < z1` (linear) are intersected.
    /// (parry3d 0.25's f32 GJK ray cast against cylinders reports hits for rays up to a few
    /// millimetres off tangency at a metre, which is exactly the limb case, so it is not used.)
    pub fn occludes(&self, c: &Vector3<f64>, a: &Vector3<f64>, p: &Point3<f64>) -> bool {
        let d = p.coords; // segment origin + s d, s in [0, 1)
        let w = -c;
        let (wa, da) = (w.dot(a), d.dot(a));
        let wp = w - a * wa;
        let dp = d - a * da;
        let qa = dp.dot(&dp);
        let qb = 2.0 * wp.dot(&dp);
        // Early out: the segment's line passes the axis farther than the widest section's radius
        // (the test below for r_max fails, hence for every section).
        let rmax = self.max_radius();
        let qc_max = wp.dot(&wp) - rmax * rmax;
        if (qa < 1e-18 && qc_max >= 0.0) || (qa >= 1e-18 && qb * qb - 4.0 * qa * qc_max <= 0.0) {
            return false;
        }
        for sec in &self.sections {
            // Interval where the axial coordinate is inside the section.
            let (mut lo, mut hi): (f64, f64) = (0.0, 1.0 - 1e-9);
            if da.abs() < 1e-15 {
                if wa <= sec.z0 || wa >= sec.z1 {
                    continue;
                }
            } else {
                let (s0, s1) = ((sec.z0 - wa) / da, (sec.z1 - wa) / da);
                lo = lo.max(s0.min(s1));
                hi = hi.min(s0.max(s1));
            }
            if lo >= hi {
                continue;
            }
            // Interval where the radial distance is below the radius.
            let qc = wp.dot(&wp) - sec.r * sec.r;
            if qa < 1e-18 {
                if qc < 0.0 {
                    return true;
                }
                continue;
            }
            let disc = qb * qb - 4.0 * qa * qc;
            if disc <= 0.0 {
                continue;
            }
            let sq = disc.sqrt();
            let (r0, r1) = ((-qb - sq) / (2.0 * qa), (-qb + sq) / (2.0 * qa));
            if r0.max(lo) < r1.min(hi) {
                return true;
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_and_ray_occlusion() {
        let m = CylinderModel::new(&TubeModel::default()).unwrap();
        assert_eq!(m.sections.len(), 3);
        assert!((m.length - 0.150).abs() < 1e-12);
        assert_eq!(m.radius_at(0.06), 0.0115);
        assert_eq!(m.neighbour_radius(1, 1), 0.0115);
        assert_eq!(m.neighbour_radius(2, 1), 0.0);
        // Tube 1 m in front of the camera, axis along camera x.
        let (c, a) = (Vector3::new(0.0, 0.0, 1.0), Vector3::x());
        // A point behind the tube is occluded, one in front or beside it is not.
        assert!(m.occludes(&c, &a, &Point3::new(0.0, 0.0, 1.1)));
        assert!(!m.occludes(&c, &a, &Point3::new(0.0, 0.0, 0.98)));
        assert!(!m.occludes(&c, &a, &Point3::new(0.0, 0.05, 1.1)));
        // Past the seal end along +x nothing blocks.
        assert!(!m.occludes(&c, &a, &Point3::new(0.1, 0.0, 1.1)));
    }
}
