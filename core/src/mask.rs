//! Binary masks and COCO run-length encoding (RLE), bit-compatible with pycocotools' `maskApi.c`.
//!
//! - [`BinaryMask`]: a row-major 0/1 image, `data[y * width + x]`.
//! - [`Rle`]: COCO RLE. Pixels are visited in **column-major** (Fortran) order, index
//!   `x * h + y`, and `counts` alternates run lengths starting with a (possibly empty) run of
//!   zeros. `size` is `[h, w]` as COCO writes it.
//!
//! The compressed string form ([`Rle::to_compressed_string`]) is pycocotools' `rleToString`:
//! each count (from the fourth on, the difference to the count two places earlier) is written
//! as signed 5-bit chunks, least significant first, bit `0x20` meaning "more chunks follow",
//! each chunk offset by 48 to make printable ASCII.

use crate::error::CoreError;

mod poly;

/// A binary mask, row-major, one byte per pixel holding 0 or 1.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BinaryMask {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major values, `data[y * width + x]`, each 0 or 1.
    pub data: Vec<u8>,
}

impl BinaryMask {
    /// An all-zero mask.
    pub fn new(width: usize, height: usize) -> Self {
        BinaryMask { width, height, data: vec![0; width * height] }
    }

    /// A mask with pixel `(x, y)` set where `f(x, y)` is true.
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> bool) -> Self {
        let mut data = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y) as u8);
            }
        }
        BinaryMask { width, height, data }
    }

    /// Whether pixel `(x, y)` is set (false outside the mask).
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> bool {
        x < self.width && y < self.height && self.data[y * self.width + x] != 0
    }

    /// Sets pixel `(x, y)`; ignored outside the mask.
    #[inline]
    pub fn set(&mut self, x: usize, y: usize, value: bool) {
        if x < self.width && y < self.height {
            self.data[y * self.width + x] = value as u8;
        }
    }

    /// The mask dilated by `r` pixels in 4-neighbour steps (an L1 diamond of radius `r`).
    /// Only the set pixels' bounding box grown by `r` is processed.
    pub fn dilated(&self, r: usize) -> BinaryMask {
        self.morphed(r, true, true)
    }

    /// The mask eroded by `r` pixels in 4-neighbour steps; pixels on the image border are
    /// cleared at each step. Only the set pixels' bounding box is processed.
    pub fn eroded(&self, r: usize) -> BinaryMask {
        self.morphed(r, false, true)
    }

    /// The mask eroded by `r` pixels in 4-neighbour steps, where pixels beyond the image border
    /// count as set: the border does not erode, so a region cut by the border keeps its edge
    /// there (a tube cut by the image's edge keeps its pixels on that edge).
    pub fn eroded_within_image(&self, r: usize) -> BinaryMask {
        self.morphed(r, false, false)
    }

    /// The mask dilated by `r` pixels as [`BinaryMask::dilated`], kept only within the set
    /// pixels' bounding box grown by `r + 1` (clipped to the image): nothing outside that
    /// window is set, so the image-sized copy is not made.
    pub fn dilated_window(&self, r: usize) -> MaskWindow {
        self.morphed_window(self.bbox(), r, true, true)
    }

    /// `r` steps of 4-neighbour dilation (`grow`) or erosion (which clears the pixels on the
    /// image border when `border_erodes`) of the whole mask: [`BinaryMask::morphed_window`]
    /// written over a copy of `self`.
    fn morphed(&self, r: usize, grow: bool, border_erodes: bool) -> BinaryMask {
        let win = self.morphed_window(self.bbox(), r, grow, border_erodes);
        let mut out = self.clone();
        let ww = win.mask.width;
        for (j, row) in win.mask.data.chunks_exact(ww.max(1)).enumerate().take(win.mask.height) {
            let at = (win.y0 + j) * self.width + win.x0;
            out.data[at..at + ww].copy_from_slice(row);
        }
        out
    }

    /// `r` steps of 4-neighbour dilation (`grow`) or erosion within the set pixels' bounding
    /// box grown by `r + 1` (clipped to the image): nothing outside it can change, and it holds
    /// no set pixel. A step sets (dilation) or keeps (erosion) a pixel when its 4-neighbourhood
    /// has one set pixel (dilation) or is all set (erosion), so `r` steps reach exactly the
    /// pixels within city-block distance `r`. The window is padded by one pixel: clear, except
    /// beyond the image border in an erosion without `border_erodes`, where it counts as set
    /// (the border does not erode). Each step is a few byte-wise ORs or ANDs of whole rows.
    /// `bbox` is the set pixels' bounding box ([`BinaryMask::bbox`]).
    fn morphed_window(&self, bbox: [f64; 4], r: usize, grow: bool, border_erodes: bool) -> MaskWindow {
        let [bx, by, bw, bh] = bbox;
        if bw == 0.0 {
            return MaskWindow { x0: 0, y0: 0, mask: BinaryMask::new(0, 0) };
        }
        let (w, h) = (self.width, self.height);
        let x0 = (bx as usize).saturating_sub(r + 1);
        let y0 = (by as usize).saturating_sub(r + 1);
        let x1 = (bx as usize + bw as usize + r + 1).min(w);
        let y1 = (by as usize + bh as usize + r + 1).min(h);
        let (ww, wh) = (x1 - x0, y1 - y0);
        let pw = ww + 2;
        let pad = |image_border: bool| (!grow && !border_erodes && image_border) as u8;
        let mut cur = vec![pad(y0 == 0); pw * (wh + 2)];
        cur[(wh + 1) * pw..].fill(pad(y1 == h));
        for j in 0..wh {
            let row = &mut cur[(j + 1) * pw..(j + 2) * pw];
            row[0] = pad(x0 == 0);
            row[pw - 1] = pad(x1 == w);
            row[1..=ww].copy_from_slice(&self.data[(y0 + j) * w + x0..][..ww]);
        }
        let mut next = cur.clone();
        for _ in 0..r {
            for j in 1..=wh {
                let (up, mid, down) = (&cur[(j - 1) * pw + 1..][..ww], &cur[j * pw..][..pw], &cur[(j + 1) * pw + 1..][..ww]);
                let (left, centre, right) = (&mid[..ww], &mid[1..=ww], &mid[2..]);
                let out = &mut next[j * pw + 1..][..ww];
                if grow {
                    for i in 0..ww {
                        out[i] = centre[i] | left[i] | right[i] | up[i] | down[i];
                    }
                } else {
                    for i in 0..ww {
                        out[i] = centre[i] & left[i] & right[i] & up[i] & down[i];
                    }
                }
            }
            std::mem::swap(&mut cur, &mut next);
        }
        let mut data = Vec::with_capacity(ww * wh);
        for j in 1..=wh {
            data.extend_from_slice(&cur[j * pw + 1..][..ww]);
        }
        MaskWindow { x0, y0, mask: BinaryMask { width: ww, height: wh, data } }
    }

    /// The `w x h` window whose top-left pixel is `(x0, y0)`: pixel `(x, y)` of the result is
    /// pixel `(x0 + x, y0 + y)` of `self` (clear where that lies outside `self`).
    pub fn crop(&self, x0: usize, y0: usize, w: usize, h: usize) -> BinaryMask {
        let mut out = BinaryMask::new(w, h);
        let xs = x0.min(self.width)..(x0 + w).min(self.width);
        for y in y0..(y0 + h).min(self.height) {
            let src = &self.data[y * self.width + xs.start..y * self.width + xs.end];
            let dst = (y - y0) * w;
            out.data[dst..dst + src.len()].copy_from_slice(src);
        }
        out
    }

    /// Number of set pixels.
    pub fn area(&self) -> u64 {
        self.data.iter().filter(|&&v| v != 0).count() as u64
    }

    /// Tight bounding box of the set pixels as COCO `[x, y, w, h]` in pixels (integer pixel
    /// indices: `x` is the first set column, `w` the number of columns spanned); all zero when
    /// the mask is empty. Identical to `Rle::from_mask(self).to_bbox()`.
    pub fn bbox(&self) -> [f64; 4] {
        let w = self.width;
        if w == 0 {
            return [0.0; 4];
        }
        let row = |y: usize| &self.data[y * w..(y + 1) * w];
        // The first and last rows with a set pixel, then, on the rows between, only the parts
        // left and right of the columns found so far are searched (word by word).
        let Some(y0) = (0..self.height).find(|&y| any_set(row(y))) else { return [0.0; 4] };
        let y1 = (y0..self.height).rev().find(|&y| any_set(row(y))).unwrap_or(y0);
        let (mut x0, mut x1) = (w, 0);
        for y in y0..=y1 {
            let r = row(y);
            if let Some(x) = first_set(&r[..x0]) {
                x0 = x;
            }
            let from = (x1 + 1).min(w).max(x0);
            if let Some(x) = last_set(&r[from..]) {
                x1 = from + x;
            }
        }
        [x0 as f64, y0 as f64, (x1 - x0 + 1) as f64, (y1 - y0 + 1) as f64]
    }
}

/// A [`BinaryMask`] whose set pixels' bounding box is known: what a detection's mask is decoded
/// into ([`Rle::to_bounded_mask`]). The operations that only need the box and what lies in it
/// ([`BoundedMask::bbox`], [`BoundedMask::dilated_window`], [`Rle::from_bounded_mask`]) then
/// cost the box, not the image (a 20-megapixel frame's scan for each). Read-only (it derefs to
/// the mask), so the box stays right.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundedMask {
    mask: BinaryMask,
    bbox: [f64; 4],
}

impl BoundedMask {
    /// `mask` with its bounding box found by one scan ([`BinaryMask::bbox`]).
    pub fn new(mask: BinaryMask) -> Self {
        let bbox = mask.bbox();
        BoundedMask { mask, bbox }
    }

    /// Tight bounding box of the set pixels, COCO `[x, y, w, h]` in pixels, as
    /// [`BinaryMask::bbox`] gives it.
    pub fn bbox(&self) -> [f64; 4] {
        self.bbox
    }

    /// [`BinaryMask::dilated_window`] within the known box.
    pub fn dilated_window(&self, r: usize) -> MaskWindow {
        self.mask.morphed_window(self.bbox, r, true, true)
    }

    /// The mask itself.
    pub fn into_mask(self) -> BinaryMask {
        self.mask
    }
}

impl From<BinaryMask> for BoundedMask {
    fn from(mask: BinaryMask) -> Self {
        BoundedMask::new(mask)
    }
}

impl std::ops::Deref for BoundedMask {
    type Target = BinaryMask;
    fn deref(&self) -> &BinaryMask {
        &self.mask
    }
}

/// Whether any byte of `s` is nonzero, 32 bytes per test (four words OR-ed).
fn any_set(s: &[u8]) -> bool {
    let mut blocks = s.chunks_exact(32);
    for b in blocks.by_ref() {
        let word = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().unwrap_or([0; 8]));
        if word(0) | word(8) | word(16) | word(24) != 0 {
            return true;
        }
    }
    blocks.remainder().iter().any(|&v| v != 0)
}

/// Index of the first nonzero byte of `s`, read eight bytes at a time.
fn first_set(s: &[u8]) -> Option<usize> {
    let mut words = s.chunks_exact(8);
    for (i, c) in words.by_ref().enumerate() {
        let v = u64::from_le_bytes(c.try_into().unwrap_or([0; 8]));
        if v != 0 {
            return Some(8 * i + (v.trailing_zeros() / 8) as usize);
        }
    }
    let base = s.len() - words.remainder().len();
    words.remainder().iter().position(|&b| b != 0).map(|p| base + p)
}

/// Index of the last nonzero byte of `s`, read eight bytes at a time.
fn last_set(s: &[u8]) -> Option<usize> {
    let whole = s.len() - s.len() % 8;
    if let Some(p) = s[whole..].iter().rposition(|&b| b != 0) {
        return Some(whole + p);
    }
    for (i, c) in s[..whole].chunks_exact(8).enumerate().rev() {
        let v = u64::from_le_bytes(c.try_into().unwrap_or([0; 8]));
        if v != 0 {
            return Some(8 * i + 7 - (v.leading_zeros() / 8) as usize);
        }
    }
    None
}

/// A window of an image-sized mask: pixel `(x, y)` of `mask` is image pixel
/// `(x0 + x, y0 + y)`, and every image pixel outside the window is clear.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MaskWindow {
    /// Image column of the window's first column.
    pub x0: usize,
    /// Image row of the window's first row.
    pub y0: usize,
    /// The window's pixels.
    pub mask: BinaryMask,
}

impl MaskWindow {
    /// Whether image pixel `(x, y)` is set (false outside the window).
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> bool {
        x >= self.x0 && y >= self.y0 && self.mask.get(x - self.x0, y - self.y0)
    }
}

/// Most boundary points [`Rle::from_polygons`] walks for one polygon (`2^24`, about 3.4 million
/// pixels of perimeter, far beyond any tube outline in a 5472 x 3648 image).
pub const MAX_POLYGON_WALK: u64 = 1 << 24;

/// Most pixels (`h * w`) of a mask that a detections file may carry (`2^27`, about 6.7 times a
/// full-resolution 5472 x 3648 image); decoding allocates one byte per pixel.
pub const MAX_MASK_PIXELS: u64 = 1 << 27;

/// COCO run-length encoding of a binary mask, column-major, runs alternating from zeros.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rle {
    /// `[h, w]`: image height and width in pixels (COCO order).
    pub size: [u32; 2],
    /// Run lengths, alternating 0-runs and 1-runs, starting with a 0-run (which may be 0).
    pub counts: Vec<u32>,
}

impl Rle {
    /// Image height in pixels.
    pub fn height(&self) -> u32 {
        self.size[0]
    }
    /// Image width in pixels.
    pub fn width(&self) -> u32 {
        self.size[1]
    }

    /// Encodes a mask (any non-zero byte counts as set), like `rleEncode`: column-major runs,
    /// starting with a (possibly empty) run of clear pixels. Only the set pixels' bounding box
    /// ([`BinaryMask::bbox`], word-wise) is read pixel by pixel; the clear pixels around it
    /// join the runs by count, so a small tube on a 20-megapixel frame costs its box, not the
    /// frame.
    pub fn from_mask(mask: &BinaryMask) -> Rle {
        Rle::from_mask_in(mask, mask.bbox())
    }

    /// [`Rle::from_mask`] of a mask whose bounding box is known: only the box is read.
    pub fn from_bounded_mask(mask: &BoundedMask) -> Rle {
        Rle::from_mask_in(mask, mask.bbox())
    }

    /// [`Rle::from_mask`] with the set pixels' bounding box `bbox` given.
    fn from_mask_in(mask: &BinaryMask, bbox: [f64; 4]) -> Rle {
        let (w, h) = (mask.width, mask.height);
        let [bx, by, bw, bh] = bbox;
        if bw == 0.0 {
            return Rle { size: [h as u32, w as u32], counts: vec![(w * h) as u32] };
        }
        let (x0, y0) = (bx as usize, by as usize);
        let (x1, y1) = (x0 + bw as usize - 1, y0 + bh as usize - 1);
        let mut counts = Vec::new();
        let mut prev = false;
        // Clear pixels before (x0, y0) in column-major order.
        let mut run = (x0 * h + y0) as u32;
        let clear = |n: usize, prev: &mut bool, run: &mut u32, counts: &mut Vec<u32>| {
            if n > 0 {
                if *prev {
                    counts.push(*run);
                    *run = 0;
                    *prev = false;
                }
                *run += n as u32;
            }
        };
        for x in x0..=x1 {
            for y in y0..=y1 {
                let v = mask.data[y * w + x] != 0;
                if v != prev {
                    counts.push(run);
                    run = 0;
                    prev = v;
                }
                run += 1;
            }
            // Below the box in this column, and above it in the next one (all clear).
            clear(h - 1 - y1 + if x < x1 { y0 } else { 0 }, &mut prev, &mut run, &mut counts);
        }
        // The columns right of the box.
        clear((w - 1 - x1) * h, &mut prev, &mut run, &mut counts);
        counts.push(run);
        Rle { size: [h as u32, w as u32], counts }
    }

    /// Decodes into a row-major mask. Errors when the counts do not sum to `h * w`. A run of
    /// set pixels is written column segment by column segment.
    pub fn to_mask(&self) -> Result<BinaryMask, CoreError> {
        Ok(self.to_bounded_mask()?.into_mask())
    }

    /// [`Rle::to_mask`] with the set pixels' tight bounding box ([`BinaryMask::bbox`]), found
    /// while decoding.
    pub fn to_bounded_mask(&self) -> Result<BoundedMask, CoreError> {
        self.check()?;
        let (h, w) = (self.size[0] as usize, self.size[1] as usize);
        let mut mask = BinaryMask::new(w, h);
        let mut pos = 0usize;
        let mut value = false;
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for &c in &self.counts {
            let end = pos + c as usize;
            if value {
                let mut i = pos;
                while i < end {
                    let (x, y) = (i / h, i % h);
                    let n = (end - i).min(h - y);
                    for yy in y..y + n {
                        mask.data[yy * w + x] = 1;
                    }
                    (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y + n - 1));
                    i += n;
                }
            }
            pos = end;
            value = !value;
        }
        let bbox = if x0 == usize::MAX { [0.0; 4] } else { [x0 as f64, y0 as f64, (x1 - x0 + 1) as f64, (y1 - y0 + 1) as f64] };
        Ok(BoundedMask { mask, bbox })
    }

    /// Checks that the counts sum to `h * w` (what every valid COCO RLE satisfies).
    pub fn check(&self) -> Result<(), CoreError> {
        let total: u64 = self.counts.iter().map(|&c| c as u64).sum();
        let expect = self.size[0] as u64 * self.size[1] as u64;
        if total != expect {
            return Err(CoreError::invalid("RLE", format!("counts sum to {total} but size {}x{} (h x w) has {expect} pixels", self.size[0], self.size[1])));
        }
        Ok(())
    }

    /// Number of set pixels: the sum of the odd-indexed counts (`rleArea`).
    pub fn area(&self) -> u64 {
        self.counts.iter().skip(1).step_by(2).map(|&c| c as u64).sum()
    }

    /// Bounding box `[x, y, w, h]` exactly as `rleToBbox`: when a run of ones wraps from one
    /// column into the next, the box spans the full image height.
    pub fn to_bbox(&self) -> [f64; 4] {
        let h = self.size[0] as u64;
        let w = self.size[1] as u64;
        let m = (self.counts.len() / 2) * 2;
        if m == 0 || h == 0 {
            return [0.0; 4];
        }
        let (mut xs, mut ys, mut xe, mut ye) = (w, h, 0u64, 0u64);
        let mut cc: u64 = 0;
        let mut xp = 0u64;
        for j in 0..m {
            cc += self.counts[j] as u64;
            let t = cc.wrapping_sub((j % 2) as u64);
            let y = t % h;
            let x = (t - y) / h;
            if j % 2 == 0 {
                xp = x;
            } else if xp < x {
                ys = 0;
                ye = h - 1;
            }
            xs = xs.min(x);
            xe = xe.max(x);
            ys = ys.min(y);
            ye = ye.max(y);
        }
        [xs as f64, ys as f64, (xe as f64) - (xs as f64) + 1.0, (ye as f64) - (ys as f64) + 1.0]
    }

    /// Union (`intersect == false`) or intersection of several RLEs, like `rleMerge`.
    /// An empty list gives an empty 0x0 RLE; differing sizes are an error.
    pub fn merge(rles: &[Rle], intersect: bool) -> Result<Rle, CoreError> {
        let Some(first) = rles.first() else {
            return Ok(Rle { size: [0, 0], counts: Vec::new() });
        };
        let mut acc = first.counts.clone();
        for (i, b) in rles.iter().enumerate().skip(1) {
            if b.size != first.size {
                return Err(CoreError::invalid("RLE merge", format!("mask {i} has size {:?} but mask 0 has {:?} (h, w)", b.size, first.size)));
            }
            acc = merge_two(&acc, &b.counts, intersect);
        }
        Ok(Rle { size: first.size, counts: acc })
    }

    /// IoU of every detection against every ground truth, like `maskUtils.iou`: returns
    /// `ious[d * gt.len() + g]`. For a crowd ground truth the union is replaced by the detection's
    /// area (`|d ∩ g| / |d|`). Pairs of different sizes give -1; zero intersection gives 0.
    pub fn iou(dt: &[Rle], gt: &[Rle], iscrowd: &[bool]) -> Vec<f64> {
        let (m, n) = (dt.len(), gt.len());
        let db: Vec<[f64; 4]> = dt.iter().map(|r| r.to_bbox()).collect();
        let gb: Vec<[f64; 4]> = gt.iter().map(|r| r.to_bbox()).collect();
        let mut out = bbox_iou(&db, &gb, iscrowd);
        for d in 0..m {
            for g in 0..n {
                let o = &mut out[d * n + g];
                if *o > 0.0 {
                    *o = rle_pair_iou(&dt[d], &gt[g], iscrowd.get(g).copied().unwrap_or(false));
                }
            }
        }
        out
    }

    /// Rasterizes polygons exactly as pycocotools' `rleFrPoly` (each polygon separately, then
    /// their union as `frPyObjects` + `merge` do). Each polygon is `[x0, y0, x1, y1, ...]` in
    /// pixels; `h`, `w` give the image size.
    ///
    /// Errors when a polygon's boundary walk would exceed [`MAX_POLYGON_WALK`] points (the walk
    /// takes `Σ max(|5 Δx|, |5 Δy|) + 1` points per polygon and allocates them), so that a
    /// corrupt file with a coordinate like `1e9` is refused instead of exhausting memory.
    pub fn from_polygons(polys: &[Vec<f64>], h: u32, w: u32) -> Result<Rle, CoreError> {
        for (i, xy) in polys.iter().enumerate() {
            let k = xy.len() / 2;
            let walk: f64 = (0..k)
                .map(|j| {
                    let n = (j + 1) % k;
                    let (dx, dy) = (xy[2 * n] - xy[2 * j], xy[2 * n + 1] - xy[2 * j + 1]);
                    5.0 * dx.abs().max(dy.abs()) + 1.0
                })
                .sum();
            // NaN (non-finite coordinates) is refused too.
            if walk.is_nan() || walk > MAX_POLYGON_WALK as f64 {
                return Err(CoreError::invalid("segmentation", format!("polygon {i}: boundary walk of {walk:.0} points exceeds the limit of {MAX_POLYGON_WALK} (coordinates far outside the image?)")));
            }
        }
        let rles: Vec<Rle> = polys.iter().map(|p| Rle::from_polygon(p, h, w)).collect();
        Rle::merge(&rles, false)
    }

    /// Rasterizes one polygon `[x0, y0, x1, y1, ...]` exactly as `rleFrPoly`: vertices are
    /// upsampled by 5, the boundary is walked densely, and pixels whose centre lies inside are set.
    pub fn from_polygon(xy: &[f64], h: u32, w: u32) -> Rle {
        poly::rle_from_polygon(xy, h, w)
    }

    /// The RLE of the box `[x, y, w, h]`, rasterized as the polygon of its four corners
    /// (`rleFrBbox`).
    pub fn from_bbox(bb: [f64; 4], h: u32, w: u32) -> Rle {
        let (xs, ys) = (bb[0], bb[1]);
        let (xe, ye) = (xs + bb[2], ys + bb[3]);
        Rle::from_polygon(&[xs, ys, xs, ye, xe, ye, xe, ys], h, w)
    }

    /// Compressed string form, byte-identical to pycocotools' `rleToString`.
    pub fn to_compressed_string(&self) -> String {
        let mut s = Vec::with_capacity(self.counts.len() * 2);
        for i in 0..self.counts.len() {
            let mut x = self.counts[i] as i64;
            if i > 2 {
                x -= self.counts[i - 2] as i64;
            }
            loop {
                let mut c = (x & 0x1f) as u8;
                x >>= 5;
                let more = if c & 0x10 != 0 { x != -1 } else { x != 0 };
                if more {
                    c |= 0x20;
                }
                s.push(c + 48);
                if !more {
                    break;
                }
            }
        }
        // Every byte is in 48..=111, plain ASCII.
        String::from_utf8(s).unwrap_or_default()
    }

    /// Parses the compressed string form (`rleFrString`) for an image of `size = [h, w]`.
    /// Errors on characters outside `'0'..='o'`, a truncated final count, counts out of the
    /// `u32` range, or counts that do not sum to `h * w`.
    pub fn from_compressed_string(s: &str, size: [u32; 2]) -> Result<Rle, CoreError> {
        let bytes = s.as_bytes();
        let mut counts: Vec<u32> = Vec::with_capacity(bytes.len());
        let mut p = 0usize;
        while p < bytes.len() {
            let mut x: i64 = 0;
            let mut k = 0u32;
            loop {
                let Some(&b) = bytes.get(p) else {
                    return Err(CoreError::invalid("RLE string", format!("truncated count at byte {p}")));
                };
                if !(48..=111).contains(&b) {
                    return Err(CoreError::invalid("RLE string", format!("byte {p} is {:?}, outside the RLE alphabet '0'..'o'", b as char)));
                }
                if k >= 12 {
                    return Err(CoreError::invalid("RLE string", format!("count too long at byte {p}")));
                }
                let c = (b - 48) as i64;
                x |= (c & 0x1f) << (5 * k);
                p += 1;
                k += 1;
                if c & 0x20 == 0 {
                    if c & 0x10 != 0 {
                        x |= -1i64 << (5 * k);
                    }
                    break;
                }
            }
            let m = counts.len();
            if m > 2 {
                x += counts[m - 2] as i64;
            }
            let v = u32::try_from(x).map_err(|_| CoreError::invalid("RLE string", format!("count {m} decodes to {x}, outside 0..2^32")))?;
            counts.push(v);
        }
        let rle = Rle { size, counts };
        rle.check()?;
        Ok(rle)
    }
}

/// The runs of two RLE count lists of the same size walked together, as the loops of
/// `rleMerge` and `rleIou` walk them: each item is a stretch of pixels (possibly empty, where a
/// count is 0) and whether it lies in the first and in the second mask.
struct JointRuns<'a> {
    a: &'a [u32],
    b: &'a [u32],
    /// Pixels left in the current run of each list, and the index of each list's next run.
    left: (u32, u32),
    next: (usize, usize),
    /// Whether the current runs are foreground.
    inside: (bool, bool),
    done: bool,
}

impl<'a> JointRuns<'a> {
    fn new(a: &'a [u32], b: &'a [u32]) -> Self {
        JointRuns { a, b, left: (a.first().copied().unwrap_or(0), b.first().copied().unwrap_or(0)), next: (1, 1), inside: (false, false), done: false }
    }
}

impl Iterator for JointRuns<'_> {
    /// `(pixels, in a, in b)`.
    type Item = (u32, bool, bool);

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let c = self.left.0.min(self.left.1);
        let item = (c, self.inside.0, self.inside.1);
        self.left.0 -= c;
        if self.left.0 == 0 && self.next.0 < self.a.len() {
            (self.left.0, self.next.0, self.inside.0) = (self.a[self.next.0], self.next.0 + 1, !self.inside.0);
        }
        self.left.1 -= c;
        if self.left.1 == 0 && self.next.1 < self.b.len() {
            (self.left.1, self.next.1, self.inside.1) = (self.b[self.next.1], self.next.1 + 1, !self.inside.1);
        }
        self.done = self.left.0 == 0 && self.left.1 == 0;
        Some(item)
    }
}

/// Merges two count lists of the same size (union or intersection), as in `rleMerge`.
fn merge_two(a: &[u32], b: &[u32], intersect: bool) -> Vec<u32> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut v, mut run) = (false, 0u32);
    for (c, va, vb) in JointRuns::new(a, b) {
        let now = if intersect { va && vb } else { va || vb };
        if now != v {
            out.push(run);
            (v, run) = (now, 0);
        }
        run += c;
    }
    out.push(run);
    out
}

/// Mask IoU of one pair, as the inner loop of `rleIou` (sizes must match, else -1).
fn rle_pair_iou(d: &Rle, g: &Rle, crowd: bool) -> f64 {
    if d.size != g.size {
        return -1.0;
    }
    let (mut inter, mut union) = (0u64, 0u64);
    for (c, va, vb) in JointRuns::new(&d.counts, &g.counts) {
        if va || vb {
            union += c as u64;
            if va && vb {
                inter += c as u64;
            }
        }
    }
    if inter == 0 {
        union = 1;
    } else if crowd {
        union = d.area();
    }
    inter as f64 / union as f64
}

/// Box IoU of every detection box against every ground-truth box, like `bbIou`: returns
/// `ious[d * gt.len() + g]`, boxes `[x, y, w, h]`. For a crowd ground truth the union is the
/// detection's area. Disjoint or touching boxes give 0.
pub fn bbox_iou(dt: &[[f64; 4]], gt: &[[f64; 4]], iscrowd: &[bool]) -> Vec<f64> {
    let n = gt.len();
    let mut out = vec![0.0; dt.len() * n];
    for (g, gb) in gt.iter().enumerate() {
        let ga = gb[2] * gb[3];
        let crowd = iscrowd.get(g).copied().unwrap_or(false);
        for (d, db) in dt.iter().enumerate() {
            let da = db[2] * db[3];
            let w = (db[2] + db[0]).min(gb[2] + gb[0]) - db[0].max(gb[0]);
            if w <= 0.0 {
                continue;
            }
            let h = (db[3] + db[1]).min(gb[3] + gb[1]) - db[1].max(gb[1]);
            if h <= 0.0 {
                continue;
            }
            let i = w * h;
            let u = if crowd { da } else { da + ga - i };
            out[d * n + g] = i / u;
        }
    }
    out
}

/// Greedy suppression by mask IoU. `masks` come in decreasing order of score; each is kept
/// unless its IoU ([`Rle::iou`]) with an earlier kept mask exceeds `max_iou`. An entry without
/// a mask (`None`) is kept and suppresses nothing. Returns whether each entry is kept.
pub fn keep_by_iou(masks: &[Option<&Rle>], max_iou: f64) -> Vec<bool> {
    let mut kept: Vec<Rle> = Vec::new();
    masks
        .iter()
        .map(|m| {
            let Some(m) = m else { return true };
            let overlaps = !kept.is_empty() && Rle::iou(std::slice::from_ref(*m), &kept, &vec![false; kept.len()]).iter().any(|&iou| iou > max_iou);
            if !overlaps {
                kept.push((*m).clone());
            }
            !overlaps
        })
        .collect()
}

#[cfg(test)]
mod keep_by_iou_tests {
    use super::*;

    #[test]
    fn a_mask_overlapping_a_kept_one_is_dropped_and_a_dropped_one_suppresses_nothing() {
        let band = |x0: usize, x1: usize| Rle::from_mask(&BinaryMask::from_fn(20, 10, |x, y| (x0..x1).contains(&x) && (2..6).contains(&y)));
        // b overlaps a at IoU 32/40 = 0.8; c overlaps b at 24/40 but a only at 16/40: b is
        // dropped, so c stays; the fourth has no mask.
        let (a, b, c) = (band(0, 8), band(0, 10), band(4, 10));
        assert_eq!(keep_by_iou(&[Some(&a), Some(&b), Some(&c), None], 0.5), vec![true, false, true, true]);
        assert_eq!(keep_by_iou(&[Some(&a), Some(&b), Some(&c)], 1.0), vec![true, true, true]);
        assert!(keep_by_iou(&[], 0.5).is_empty());
    }
}

#[cfg(test)]
mod joint_runs_tests {
    use super::*;

    /// Masks of every kind of run structure: empty, full, starting with foreground, single
    /// pixels, from a fixed pseudo-random sequence.
    fn masks() -> Vec<BinaryMask> {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut out = vec![BinaryMask::from_fn(7, 5, |_, _| false), BinaryMask::from_fn(7, 5, |_, _| true)];
        for density in [1u64, 3, 5, 7] {
            for _ in 0..12 {
                out.push(BinaryMask::from_fn(7, 5, |_, _| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    state % 8 < density
                }));
            }
        }
        out
    }

    #[test]
    fn merge_and_iou_equal_their_pixelwise_definitions() {
        let masks = masks();
        for a in &masks {
            for b in &masks {
                let (ra, rb) = (Rle::from_mask(a), Rle::from_mask(b));
                let inter = a.data.iter().zip(&b.data).filter(|(x, y)| **x == 1 && **y == 1).count();
                let union = a.data.iter().zip(&b.data).filter(|(x, y)| **x == 1 || **y == 1).count();
                let or = Rle::merge(&[ra.clone(), rb.clone()], false).unwrap();
                let and = Rle::merge(&[ra.clone(), rb.clone()], true).unwrap();
                assert_eq!(or, Rle::from_mask(&BinaryMask::from_fn(7, 5, |x, y| a.data[y * 7 + x] == 1 || b.data[y * 7 + x] == 1)));
                assert_eq!(and, Rle::from_mask(&BinaryMask::from_fn(7, 5, |x, y| a.data[y * 7 + x] == 1 && b.data[y * 7 + x] == 1)));
                let iou = Rle::iou(std::slice::from_ref(&ra), std::slice::from_ref(&rb), &[false])[0];
                let expected = if inter == 0 { 0.0 } else { inter as f64 / union as f64 };
                assert!((iou - expected).abs() < 1e-12, "iou {iou} against {expected}");
                // A crowd ground truth: the detection's own area is the union.
                let crowd = Rle::iou(std::slice::from_ref(&ra), std::slice::from_ref(&rb), &[true])[0];
                let area = a.data.iter().filter(|x| **x == 1).count();
                let expected = if inter == 0 { 0.0 } else { inter as f64 / area as f64 };
                assert!((crowd - expected).abs() < 1e-12, "crowd iou {crowd} against {expected}");
            }
        }
    }
}
