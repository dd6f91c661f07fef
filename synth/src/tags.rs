//! AprilTag images drawn exactly as the AprilTag 3 detector reads them.
//!
//! The code tables come from the bundled C library (`apriltag_sys::tag36h11_create()` and
//! friends): `codes`, `bit_x`, `bit_y`, `width_at_border`, `total_width`, `reversed_border`.
//! A tag of family "36h11" is a `total_width` = 10 cell square: a white outer ring, a black
//! ring, and a 6x6 data area; bit `i` (most significant first) sits at cell
//! `(bit_x[i], bit_y[i])` counted from the outer corner of the black ring, 1 = white.
//!
//! Tag-plane frame (metres), the same one `tubeloc-calib` uses for poses: origin at the tag
//! centre, `u` (x) to the right and `v` (y) down as the tag is printed, z into the tag. The
//! tag "size" `s` is the edge of the black square (`width_at_border` cells), as in the AprilTag
//! pose convention. The detector's corner `k` lies at tag-plane
//! `(-s/2, s/2)`, `(s/2, s/2)`, `(s/2, -s/2)`, `(-s/2, -s/2)` for `k = 0..3`.
//!
//! OpenCV's aruco module draws AprilTag ids rotated by 180 degrees relative to this table.

use apriltag_sys as sys;
use std::sync::OnceLock;

/// AprilTag families whose tables this module can draw.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum TagFamily {
    /// 36-bit codes, minimum Hamming distance 11 (the default; 587 ids).
    #[serde(rename = "tag36h11")]
    Tag36h11,
    /// 25-bit codes, minimum Hamming distance 9.
    #[serde(rename = "tag25h9")]
    Tag25h9,
    /// 16-bit codes, minimum Hamming distance 5.
    #[serde(rename = "tag16h5")]
    Tag16h5,
}

impl TagFamily {
    /// The family name as the C library spells it (`"tag36h11"`).
    pub fn name(self) -> &'static str {
        match self {
            TagFamily::Tag36h11 => "tag36h11",
            TagFamily::Tag25h9 => "tag25h9",
            TagFamily::Tag16h5 => "tag16h5",
        }
    }

    /// The family's code table (built once from the C library, then cached).
    pub fn table(self) -> &'static FamilyTable {
        static T36: OnceLock<FamilyTable> = OnceLock::new();
        static T25: OnceLock<FamilyTable> = OnceLock::new();
        static T16: OnceLock<FamilyTable> = OnceLock::new();
        // SAFETY: the create functions return a fully initialized family struct that we read
        // and then free with the matching destroy function.
        unsafe {
            match self {
                TagFamily::Tag36h11 => T36.get_or_init(|| FamilyTable::copy(sys::tag36h11_create(), sys::tag36h11_destroy)),
                TagFamily::Tag25h9 => T25.get_or_init(|| FamilyTable::copy(sys::tag25h9_create(), sys::tag25h9_destroy)),
                TagFamily::Tag16h5 => T16.get_or_init(|| FamilyTable::copy(sys::tag16h5_create(), sys::tag16h5_destroy)),
            }
        }
    }
}

/// A copy of the C library's family description.
#[derive(Clone, Debug)]
pub struct FamilyTable {
    /// Code words, one per id; bit `nbits-1-i` is the value of bit `i`.
    pub codes: Vec<u64>,
    /// Cell column of bit `i`, counted from the outer corner of the black border.
    pub bit_x: Vec<u32>,
    /// Cell row of bit `i`.
    pub bit_y: Vec<u32>,
    /// Cells across the outer edge of the black border (8 for tag36h11).
    pub width_at_border: i32,
    /// Cells across the whole tag including the white ring (10 for tag36h11).
    pub total_width: i32,
    /// True for families whose border is reversed (white inside black); not drawn here.
    pub reversed_border: bool,
}

impl FamilyTable {
    unsafe fn copy(ptr: *mut sys::apriltag_family_t, destroy: unsafe extern "C" fn(*mut sys::apriltag_family_t)) -> Self {
        let f = &*ptr;
        let n = f.nbits as usize;
        let table = FamilyTable {
            codes: std::slice::from_raw_parts(f.codes, f.ncodes as usize).to_vec(),
            bit_x: std::slice::from_raw_parts(f.bit_x, n).to_vec(),
            bit_y: std::slice::from_raw_parts(f.bit_y, n).to_vec(),
            width_at_border: f.width_at_border,
            total_width: f.total_width,
            reversed_border: f.reversed_border,
        };
        destroy(ptr);
        table
    }

    /// Number of ids in the family.
    pub fn len(&self) -> usize {
        self.codes.len()
    }

    /// True when the family has no codes (never for the built-in families).
    pub fn is_empty(&self) -> bool {
        self.codes.is_empty()
    }
}

/// The tag image of `id` as `total_width x total_width` cells, row-major, `true` = white,
/// including the white outer ring and the black border. `None` when `id` is out of range.
pub fn tag_bits(family: TagFamily, id: u32) -> Option<(usize, Vec<bool>)> {
    let t = family.table();
    let code = *t.codes.get(id as usize)?;
    let n = t.total_width as usize;
    let off = ((t.total_width - t.width_at_border) / 2) as usize;
    let mut cells = vec![false; n * n];
    for y in 0..n {
        for x in 0..n {
            let ring = x < off || y < off || x >= n - off || y >= n - off;
            cells[y * n + x] = ring != t.reversed_border;
        }
    }
    let nbits = t.bit_x.len();
    for i in 0..nbits {
        let bit = (code >> (nbits - 1 - i)) & 1 == 1;
        let (x, y) = (t.bit_x[i] as usize + off, t.bit_y[i] as usize + off);
        if x < n && y < n {
            cells[y * n + x] = bit;
        }
    }
    Some((n, cells))
}

/// A tag ready for texture lookups: its cells and the physical size of its black square.
#[derive(Clone, Debug)]
pub struct TagTexture {
    /// Cells per side (`total_width`).
    pub cells_per_side: usize,
    /// Cells across the black square (`width_at_border`).
    pub cells_at_border: usize,
    /// Row-major cells, `true` = white.
    pub cells: Vec<bool>,
    /// Edge of the black square in metres.
    pub size_m: f64,
}

impl TagTexture {
    /// The texture of `id` with a black square of `size_m` metres; `None` for an unknown id.
    pub fn new(family: TagFamily, id: u32, size_m: f64) -> Option<Self> {
        let (n, cells) = tag_bits(family, id)?;
        Some(TagTexture { cells_per_side: n, cells_at_border: family.table().width_at_border as usize, cells, size_m })
    }

    /// Half the edge of the whole tag including the white ring, metres.
    pub fn half_extent(&self) -> f64 {
        0.5 * self.size_m * self.cells_per_side as f64 / self.cells_at_border as f64
    }

    /// Reflectance (0 black, 1 white) at tag-plane `(u, v)` metres from the tag centre
    /// (u right, v down as printed); `None` outside the white ring.
    #[inline]
    pub fn sample(&self, u: f64, v: f64) -> Option<f32> {
        let cell = self.size_m / self.cells_at_border as f64;
        let h = self.half_extent();
        let cx = ((u + h) / cell).floor();
        let cy = ((v + h) / cell).floor();
        let n = self.cells_per_side as f64;
        if !(0.0..n).contains(&cx) || !(0.0..n).contains(&cy) {
            return None;
        }
        Some(if self.cells[cy as usize * self.cells_per_side + cx as usize] { 1.0 } else { 0.0 })
    }

    /// Area-averaged reflectance over the square of half-width `r` metres around `(u, v)`
    /// (the exact coverage of the cell grid, so edges are anti-aliased); `None` outside.
    pub fn sample_area(&self, u: f64, v: f64, r: f64) -> Option<f32> {
        let h = self.half_extent();
        if u < -h - r || u > h + r || v < -h - r || v > h + r {
            return None;
        }
        if r <= 0.0 {
            return self.sample(u, v);
        }
        let cell = self.size_m / self.cells_at_border as f64;
        let n = self.cells_per_side as i64;
        let (x0, x1) = (u - r + h, u + r + h);
        let (y0, y1) = (v - r + h, v + r + h);
        let (mut sum, mut area) = (0.0, 0.0);
        let cx0 = ((x0 / cell).floor() as i64).max(0);
        let cx1 = ((x1 / cell).floor() as i64).min(n - 1);
        let cy0 = ((y0 / cell).floor() as i64).max(0);
        let cy1 = ((y1 / cell).floor() as i64).min(n - 1);
        for cy in cy0..=cy1 {
            let oy = (y1.min((cy + 1) as f64 * cell) - y0.max(cy as f64 * cell)).max(0.0);
            for cx in cx0..=cx1 {
                let ox = (x1.min((cx + 1) as f64 * cell) - x0.max(cx as f64 * cell)).max(0.0);
                let a = ox * oy;
                if self.cells[cy as usize * self.cells_per_side + cx as usize] {
                    sum += a;
                }
                area += a;
            }
        }
        // Outside the tag counts as white paper (the ring is white anyway).
        let total = 4.0 * r * r;
        sum += (total - area).max(0.0);
        Some((sum / total) as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tag36h11_table_matches_known_layout() {
        let t = TagFamily::Tag36h11.table();
        assert_eq!(t.len(), 587);
        assert_eq!((t.width_at_border, t.total_width, t.reversed_border), (8, 10, false));
        let (n, cells) = tag_bits(TagFamily::Tag36h11, 0).unwrap();
        assert_eq!(n, 10);
        // White outer ring, black border ring.
        for i in 0..10 {
            assert!(cells[i] && cells[90 + i] && cells[i * 10] && cells[i * 10 + 9]);
        }
        for i in 1..9 {
            assert!(!cells[10 + i] && !cells[80 + i] && !cells[i * 10 + 1] && !cells[i * 10 + 8]);
        }
        let white = cells.iter().filter(|&&c| c).count();
        // 36 ring cells + the popcount of the code.
        assert_eq!(white, 36 + t.codes[0].count_ones() as usize);
        assert!(tag_bits(TagFamily::Tag36h11, 587).is_none());
    }

    #[test]
    fn area_sampling_averages_cells() {
        let tex = TagTexture::new(TagFamily::Tag36h11, 3, 0.08).unwrap();
        let cell = 0.01;
        // Centre of the white ring's top-left cell, and of the black ring below-right of it.
        assert_eq!(tex.sample(-0.05 + 0.5 * cell, -0.05 + 0.5 * cell), Some(1.0));
        assert_eq!(tex.sample(-0.04 + 0.5 * cell, -0.04 + 0.5 * cell), Some(0.0));
        assert_eq!(tex.sample(0.051, 0.0), None);
        // A box straddling the white/black boundary of the rings by equal parts gives 0.5.
        let v = tex.sample_area(-0.04, -0.03 + 0.5 * cell, 0.002).unwrap();
        assert!((v - 0.5).abs() < 1e-6, "{v}");
    }
}
