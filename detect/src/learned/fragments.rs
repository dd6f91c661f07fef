//! Merging collinear fragments of one tube (see [`super::decode`]).
//!
//! A tube whose middle is dim, dusty or crossed by sand can fall apart into two foreground
//! components. Two groups of cells from different components are one tube when
//! - their axes are parallel: angle below `max_angle_deg`;
//! - each one's centre lies near the other's axis line: across-axis offset below `max_across`
//!   cells;
//! - the gap between their extents along the axis is below `max_gap` cells;
//! - the merged extent `E` is no longer than `length_slack × Lp`, `Lp` the larger predicted
//!   length of the two (the length head sees the whole tube, so two tubes end to end exceed it).
//!
//! Merging is transitive (union-find); the merged group keeps the strongest centre peak.

use super::net::{LENGTH_SCALE, STRIDE};

/// Thresholds of fragment merging (cells are stride-4 output cells).
#[derive(Clone, Copy, Debug)]
pub struct MergeConfig {
    /// Maximum angle between the two axes, degrees (0 switches merging off).
    pub max_angle_deg: f32,
    /// Maximum across-axis offset of either centre from the other's axis, cells.
    pub max_across: f32,
    /// Maximum gap along the axis between the two extents, cells.
    pub max_gap: f32,
    /// Maximum merged extent as a multiple of the larger predicted length.
    pub length_slack: f32,
}

/// Axis summary of a group of cells: fg-weighted centre (cells), unit direction, extent along
/// it (cells, relative to the centre), predicted length (cells), component id.
struct Summary {
    c: (f32, f32),
    u: (f32, f32),
    lo: f32,
    hi: f32,
    pred: f32,
    comp: u32,
}

fn summary(cells: &[usize], fg: &[f32], cos2: &[f32], sin2: &[f32], half: &[f32], ow: usize, comp: u32) -> Summary {
    let (mut w, mut sx, mut sy, mut c2, mut s2, mut sh) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
    for &c in cells {
        let f = fg[c];
        w += f;
        sx += f * (c % ow) as f32;
        sy += f * (c / ow) as f32;
        c2 += f * cos2[c];
        s2 += f * sin2[c];
        sh += f * half[c];
    }
    let w = w.max(1e-6);
    let th = 0.5 * s2.atan2(c2);
    let (c, u) = ((sx / w, sy / w), (th.cos(), th.sin()));
    let (mut lo, mut hi) = (f32::MAX, f32::MIN);
    for &k in cells {
        let t = ((k % ow) as f32 - c.0) * u.0 + ((k / ow) as f32 - c.1) * u.1;
        lo = lo.min(t);
        hi = hi.max(t);
    }
    Summary { c, u, lo, hi, pred: 2.0 * (sh / w).max(0.0) * LENGTH_SCALE / STRIDE as f32, comp }
}

/// Whether `a` and `b` are collinear fragments of one tube under `cfg`.
fn same_tube(a: &Summary, b: &Summary, cfg: &MergeConfig) -> bool {
    if a.comp == b.comp {
        return false;
    }
    let cos = (a.u.0 * b.u.0 + a.u.1 * b.u.1).abs().min(1.0);
    if cos.acos().to_degrees() > cfg.max_angle_deg {
        return false;
    }
    let across = |s: &Summary, p: (f32, f32)| (-(p.0 - s.c.0) * s.u.1 + (p.1 - s.c.1) * s.u.0).abs();
    if across(a, b.c) > cfg.max_across || across(b, a.c) > cfg.max_across {
        return false;
    }
    // Both extents on a's axis.
    let along = |p: (f32, f32)| (p.0 - a.c.0) * a.u.0 + (p.1 - a.c.1) * a.u.1;
    let bc = along(b.c);
    let sign = a.u.0 * b.u.0 + a.u.1 * b.u.1;
    let (blo, bhi) = if sign >= 0.0 { (bc + b.lo, bc + b.hi) } else { (bc - b.hi, bc - b.lo) };
    let gap = (blo - a.hi).max(a.lo - bhi);
    let extent = a.hi.max(bhi) - a.lo.min(blo) + 1.0;
    gap <= cfg.max_gap && extent <= cfg.length_slack * a.pred.max(b.pred)
}

/// Merges collinear fragments among `groups` (each: optional peak cell, its cells); `comp`
/// holds each cell's component id; `planes` the network's `HEADS` stride-4 planes with `fg`
/// and `heat` already turned into probabilities.
pub(crate) fn merge_collinear(groups: Vec<(Option<usize>, Vec<usize>)>, comp: &[u32], fg: &[f32], heat: &[f32], planes: &[f32], ow: usize, cfg: &MergeConfig) -> Vec<(Option<usize>, Vec<usize>)> {
    if cfg.max_angle_deg <= 0.0 || groups.len() < 2 {
        return groups;
    }
    let n = fg.len();
    let (cos2, sin2, half) = (&planes[2 * n..3 * n], &planes[3 * n..4 * n], &planes[4 * n..5 * n]);
    let sums: Vec<Summary> = groups.iter().map(|(_, cells)| summary(cells, fg, cos2, sin2, half, ow, comp[cells[0]])).collect();
    let mut parent: Vec<usize> = (0..groups.len()).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for i in 0..groups.len() {
        for j in i + 1..groups.len() {
            if same_tube(&sums[i], &sums[j], cfg) {
                let (ri, rj) = (root(&mut parent, i), root(&mut parent, j));
                parent[ri.max(rj)] = ri.min(rj);
            }
        }
    }
    let mut merged: Vec<(Option<usize>, Vec<usize>)> = Vec::new();
    let mut slot = vec![usize::MAX; groups.len()];
    for (i, (peak, cells)) in groups.into_iter().enumerate() {
        let r = root(&mut parent, i);
        if slot[r] == usize::MAX {
            slot[r] = merged.len();
            merged.push((peak, cells));
        } else {
            let m = &mut merged[slot[r]];
            m.1.extend(cells);
            m.0 = match (m.0, peak) {
                (Some(a), Some(b)) => Some(if heat[b] > heat[a] { b } else { a }),
                (a, b) => a.or(b),
            };
        }
    }
    merged
}

#[cfg(test)]
mod tests {
    use super::super::decode::{decode, DecodeConfig};
    use super::super::model::Prediction;
    use super::super::net::HEADS;
    use super::*;

    /// One diagonal bar (cells `t = -12..=12` along 30°, 3 cells wide) cut by a 3-cell gap at
    /// `t = 2..=4`, each piece with its own centre peak; the length head sees the whole bar.
    /// Beside it, a second bar of the same direction, continuing the first's axis after an
    /// 8-cell gap, whose extent together with the first exceeds the predicted length.
    fn broken_bar() -> Prediction {
        let (ow, oh) = (96, 96);
        let n = ow * oh;
        let mut p = vec![-6.0f32; HEADS * n];
        let th = 30f32.to_radians();
        let (ux, uy) = (th.cos(), th.sin());
        let mut put = |c0: (f32, f32), t0: i32, t1: i32, half: f32, peaks: &[i32]| {
            for t in t0..=t1 {
                for a in -1..=1 {
                    let (x, y) = ((c0.0 + t as f32 * ux - a as f32 * uy).round() as usize, (c0.1 + t as f32 * uy + a as f32 * ux).round() as usize);
                    let c = y * ow + x;
                    p[c] = 4.0;
                    p[2 * n + c] = (2.0 * th).cos();
                    p[3 * n + c] = (2.0 * th).sin();
                    p[4 * n + c] = half * STRIDE as f32 / LENGTH_SCALE;
                }
            }
            for &t in peaks {
                let (x, y) = ((c0.0 + t as f32 * ux).round() as usize, (c0.1 + t as f32 * uy).round() as usize);
                p[n + y * ow + x] = 2.0;
            }
        };
        // The broken bar: centre (30, 30), pieces t = -12..=1 and 5..=12, half-length 12.5 cells.
        put((30.0, 30.0), -12, 1, 12.5, &[-6]);
        put((30.0, 30.0), 5, 12, 12.5, &[8]);
        // Another tube on the same line: t = 21..=40, half-length 10 cells.
        put((30.0, 30.0), 21, 40, 10.0, &[30]);
        Prediction { planes: p, out_w: ow, out_h: oh, width: 384, height: 384, fine: None }
    }

    #[test]
    fn two_collinear_fragments_of_one_bar_decode_to_one_instance() {
        let pred = broken_bar();
        let off = DecodeConfig::default();
        assert_eq!(off.merge.max_angle_deg, 0.0, "merging is off by default");
        assert_eq!(decode(&pred, &off).len(), 3, "without merging: two fragments and the other tube");
        let on = DecodeConfig { merge: MergeConfig { max_angle_deg: 15.0, ..off.merge }, ..off };
        let inst = decode(&pred, &on);
        assert_eq!(inst.len(), 2, "{:?}", inst.iter().map(|i| i.axis).collect::<Vec<_>>());
        // The merged instance spans both fragments: about 25 cells = 100 px along the axis.
        let near = inst.iter().find(|i| i.axis.centre_px[0] < 200.0).expect("the merged bar");
        let (lo, hi) = near.mask.data.iter().enumerate().filter(|(_, &m)| m != 0).fold((f64::MAX, f64::MIN), |a, (k, _)| {
            let t = (k % 384) as f64 * 30f64.to_radians().cos() + (k / 384) as f64 * 30f64.to_radians().sin();
            (a.0.min(t), a.1.max(t))
        });
        assert!((hi - lo - 100.0).abs() < 8.0, "merged extent {} px", hi - lo);
    }
}
