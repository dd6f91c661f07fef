//! Block normal equations and their solution by the Schur complement.
//!
//! The free parameter blocks are split into *kept* blocks (intrinsics, rig extrinsics: few,
//! read by many residuals) and *eliminated* blocks (per-view board poses: many, each read by
//! the residuals of one view only). No residual reads two eliminated blocks, so the normal
//! matrix is
//!
//! ```text
//! H = | A   B |   A: kept x kept (dense), B: kept x eliminated,
//!     | Bᵀ  D |   D: block diagonal, one k x k block per eliminated block
//! ```
//!
//! and `H δ = −g` reduces to the Schur complement `S = A − B D⁻¹ Bᵀ` over the kept parameters:
//! `S δc = −g_c + B D⁻¹ g_e`, then `δe = D⁻¹ (−g_e − Bᵀ δc)` block by block. `S` is factored
//! by faer's dense Cholesky (LLᵀ); each `D` block (6 x 6 for a pose) by nalgebra's.
//! The covariance of the kept parameters is `σ² S⁻¹`, the marginal covariance of an
//! eliminated block `σ² (D⁻¹ + D⁻¹ Bᵀ S⁻¹ B D⁻¹)`.

use faer::linalg::solvers::DenseSolveCore;
use faer::prelude::*;
use faer::Side;
use nalgebra::{DMatrix, DVector};

/// Where a parameter block goes in the block normal equations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Place {
    /// Held constant.
    Fixed,
    /// Kept in the reduced system at this offset.
    Kept(usize),
    /// Eliminated: index among the eliminated blocks.
    Eliminated(usize),
}

/// Split of the free blocks and the residual groups used to assemble the block system.
pub(crate) struct Layout {
    /// Place of each parameter block.
    pub place: Vec<Place>,
    /// Size of the reduced (kept) system.
    pub kept_len: usize,
    /// Size of each eliminated block.
    pub elim_len: Vec<usize>,
    /// Residual indices per eliminated block.
    pub groups: Vec<Vec<usize>>,
    /// Residual indices that read no eliminated block.
    pub ungrouped: Vec<usize>,
}

impl Layout {
    /// Chooses the eliminated blocks greedily (free blocks read by the fewest residuals first;
    /// a block is eliminated when none of its residuals reads an already eliminated block) and
    /// groups the active residuals. `reads[k]` lists the blocks residual `k` reads
    /// (`None` for inactive residuals).
    pub fn new(sizes: &[usize], fixed: &[bool], reads: &[Option<&[usize]>]) -> Layout {
        let nb = sizes.len();
        let mut users: Vec<Vec<usize>> = vec![Vec::new(); nb];
        for (k, r) in reads.iter().enumerate() {
            if let Some(blocks) = r {
                for &b in blocks.iter() {
                    if !fixed[b] && users[b].last() != Some(&k) {
                        users[b].push(k);
                    }
                }
            }
        }
        let mut order: Vec<usize> = (0..nb).filter(|&b| !fixed[b]).collect();
        order.sort_by_key(|&b| (users[b].len(), b));
        let mut eliminated = vec![false; nb];
        let mut claimed = vec![false; reads.len()];
        for &b in &order {
            if users[b].iter().all(|&k| !claimed[k]) {
                eliminated[b] = true;
                for &k in &users[b] {
                    claimed[k] = true;
                }
            }
        }
        let mut place = vec![Place::Fixed; nb];
        let (mut kept_len, mut elim_len) = (0, Vec::new());
        for b in 0..nb {
            if fixed[b] {
                continue;
            }
            if eliminated[b] {
                place[b] = Place::Eliminated(elim_len.len());
                elim_len.push(sizes[b]);
            } else {
                place[b] = Place::Kept(kept_len);
                kept_len += sizes[b];
            }
        }
        let mut groups = vec![Vec::new(); elim_len.len()];
        let mut ungrouped = Vec::new();
        for (k, r) in reads.iter().enumerate() {
            let Some(blocks) = r else { continue };
            match blocks.iter().find_map(|&b| if let Place::Eliminated(e) = place[b] { Some(e) } else { None }) {
                Some(e) => groups[e].push(k),
                None => ungrouped.push(k),
            }
        }
        Layout { place, kept_len, elim_len, groups, ungrouped }
    }
}

/// The block normal equations `JᵀJ`, `Jᵀr` and `Σ r²` at one parameter vector.
#[derive(Clone, Debug)]
pub(crate) struct BlockNormal {
    /// `A`: kept x kept.
    pub a: DMatrix<f64>,
    /// `g_c`: kept part of `Jᵀr`.
    pub gc: DVector<f64>,
    /// `D` blocks.
    pub d: Vec<DMatrix<f64>>,
    /// `Bᵀ` blocks (k x kept).
    pub bt: Vec<DMatrix<f64>>,
    /// `g_e` blocks.
    pub ge: Vec<DVector<f64>>,
    /// `Σ r²`.
    pub cost: f64,
}

/// A run of Jacobian columns of one residual: the free parameters of one block.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Segment {
    /// Where the block goes (never [`Place::Fixed`]).
    pub place: Place,
    /// Number of parameters.
    pub len: usize,
}

fn dot(x: &[f64], y: &[f64]) -> f64 {
    x.iter().zip(y).map(|(a, b)| a * b).sum()
}

impl BlockNormal {
    /// Zeros shaped by `layout`.
    pub fn zeros(layout: &Layout) -> BlockNormal {
        Self::zeros_for(layout, |_| true)
    }

    /// Zeros shaped by `layout`, with empty (0-sized) blocks for the eliminated blocks where
    /// `has(e)` is false: the accumulator of residuals that read only eliminated block `e`.
    pub fn zeros_for(layout: &Layout, has: impl Fn(usize) -> bool) -> BlockNormal {
        let nc = layout.kept_len;
        let k = |e: usize| if has(e) { layout.elim_len[e] } else { 0 };
        let ne = layout.elim_len.len();
        BlockNormal {
            a: DMatrix::zeros(nc, nc),
            gc: DVector::zeros(nc),
            d: (0..ne).map(|e| DMatrix::zeros(k(e), k(e))).collect(),
            bt: (0..ne).map(|e| DMatrix::zeros(k(e), if k(e) > 0 { nc } else { 0 })).collect(),
            ge: (0..ne).map(|e| DVector::zeros(k(e))).collect(),
            cost: 0.0,
        }
    }

    /// Adds one residual block: residuals `r` (length m) and its Jacobian (row-major, m rows)
    /// whose columns are the runs `segs`. Only one triangle of `A` and `D` is accumulated
    /// (row ≥ column in nalgebra's column-major storage); [`BlockNormal::symmetrize`] fills
    /// the other.
    pub fn add(&mut self, r: &[f64], segs: &[Segment], jac: &[f64]) {
        let m = r.len();
        let ncols: usize = segs.iter().map(|s| s.len).sum();
        self.cost += dot(r, r);
        let nc = self.a.nrows();
        for (row, &rv) in r.iter().enumerate() {
            let jr = &jac[row * ncols..(row + 1) * ncols];
            let mut ci = 0;
            for (si, s) in segs.iter().enumerate() {
                for p in 0..s.len {
                    let v = jr[ci + p] * rv;
                    match s.place {
                        Place::Kept(o) => self.gc[o + p] += v,
                        Place::Eliminated(e) => self.ge[e][p] += v,
                        Place::Fixed => {}
                    }
                }
                let mut cj = ci;
                for (sj, t) in segs.iter().enumerate().skip(si) {
                    let same = si == sj;
                    match (s.place, t.place) {
                        (Place::Kept(oi), Place::Kept(oj)) => {
                            let a = self.a.as_mut_slice();
                            for p in 0..s.len {
                                let x = jr[ci + p];
                                let q0 = if same { p } else { 0 };
                                if oi <= oj {
                                    let dst = &mut a[(oi + p) * nc + oj + q0..(oi + p) * nc + oj + t.len];
                                    for (d, y) in dst.iter_mut().zip(&jr[cj + q0..cj + t.len]) {
                                        *d += x * y;
                                    }
                                } else {
                                    for q in q0..t.len {
                                        a[(oj + q) * nc + oi + p] += x * jr[cj + q];
                                    }
                                }
                            }
                        }
                        (Place::Kept(o), Place::Eliminated(e)) => {
                            let k = t.len;
                            let bt = self.bt[e].as_mut_slice();
                            for p in 0..s.len {
                                let x = jr[ci + p];
                                for (d, y) in bt[(o + p) * k..(o + p + 1) * k].iter_mut().zip(&jr[cj..cj + k]) {
                                    *d += x * y;
                                }
                            }
                        }
                        (Place::Eliminated(e), Place::Kept(o)) => {
                            let k = s.len;
                            let bt = self.bt[e].as_mut_slice();
                            for q in 0..t.len {
                                let y = jr[cj + q];
                                for (d, x) in bt[(o + q) * k..(o + q + 1) * k].iter_mut().zip(&jr[ci..ci + k]) {
                                    *d += x * y;
                                }
                            }
                        }
                        (Place::Eliminated(e), Place::Eliminated(f)) => {
                            debug_assert!(e == f && same, "a residual reads two eliminated blocks");
                            let k = s.len;
                            let d = self.d[e].as_mut_slice();
                            for p in 0..k {
                                let x = jr[ci + p];
                                for (dv, y) in d[p * k + p..(p + 1) * k].iter_mut().zip(&jr[ci + p..ci + k]) {
                                    *dv += x * y;
                                }
                            }
                        }
                        _ => {}
                    }
                    cj += t.len;
                }
                ci += s.len;
            }
        }
        let _ = m;
    }

    /// Copies the accumulated lower triangles of `A` and the `D` blocks to their upper ones.
    pub fn symmetrize(&mut self) {
        self.a.fill_upper_triangle_with_lower_triangle();
        for d in &mut self.d {
            d.fill_upper_triangle_with_lower_triangle();
        }
    }

    /// Adds another accumulator of the same shape.
    pub fn merge(&mut self, o: &BlockNormal) {
        self.a += &o.a;
        self.gc += &o.gc;
        for e in 0..self.d.len() {
            if o.d[e].nrows() > 0 {
                self.d[e] += &o.d[e];
                self.bt[e] += &o.bt[e];
                self.ge[e] += &o.ge[e];
            }
        }
        self.cost += o.cost;
    }

    /// Solves `(H + λ·diag(H)) δ = −g` by the Schur complement. Returns `(δc, [δe])`, or
    /// `None` when a damped block is not positive definite.
    pub fn solve(&self, lambda: f64) -> Option<(DVector<f64>, Vec<DVector<f64>>)> {
        let reduced = self.reduce(lambda)?;
        let nc = self.a.nrows();
        let dc = if nc == 0 {
            DVector::zeros(0)
        } else {
            let s = to_faer(&reduced.s);
            let llt = s.llt(Side::Lower).ok()?;
            let mut rhs = Mat::<f64>::from_fn(nc, 1, |i, _| reduced.rhs[i]);
            llt.solve_in_place(rhs.as_mut());
            DVector::from_fn(nc, |i, _| rhs[(i, 0)])
        };
        let de = (0..self.d.len()).map(|e| &reduced.dinv[e] * (-&self.ge[e] - &self.bt[e] * &dc)).collect::<Vec<_>>();
        de.iter().chain(std::iter::once(&dc)).all(|v| v.iter().all(|x| x.is_finite())).then_some((dc, de))
    }

    /// Damped `D⁻¹` blocks, Schur complement and reduced right-hand side.
    fn reduce(&self, lambda: f64) -> Option<Reduced> {
        let nc = self.a.nrows();
        let mut s = self.a.clone();
        for i in 0..nc {
            s[(i, i)] += lambda * self.a[(i, i)].max(1e-12);
        }
        let mut rhs = -&self.gc;
        let mut dinv = Vec::with_capacity(self.d.len());
        for e in 0..self.d.len() {
            let mut d = self.d[e].clone();
            for i in 0..d.nrows() {
                d[(i, i)] += lambda * self.d[e][(i, i)].max(1e-12);
            }
            let di = d.cholesky()?.inverse();
            let w = self.bt[e].transpose() * &di;
            s -= &w * &self.bt[e];
            rhs += &w * &self.ge[e];
            dinv.push(di);
        }
        Some(Reduced { s, rhs, dinv })
    }

    /// Covariance `σ²·H⁻¹` by blocks (kept block and each eliminated block's marginal), or
    /// `None` when `H` is not positive definite. Also returns the inverse condition number
    /// (smallest over the column-scaled Schur complement and `D` blocks).
    pub fn covariance(&self, sigma2: f64) -> (Option<CovarianceBlocks>, f64) {
        let mut inverse_condition = f64::INFINITY;
        for d in &self.d {
            inverse_condition = inverse_condition.min(scaled_inverse_condition(d));
        }
        let Some(reduced) = self.reduce(0.0) else { return (None, 0.0) };
        let nc = self.a.nrows();
        if nc > 0 {
            inverse_condition = inverse_condition.min(scaled_inverse_condition(&reduced.s));
        }
        let inverse_condition = if inverse_condition.is_finite() { inverse_condition } else { 0.0 };
        if inverse_condition <= 1e-14 {
            return (None, inverse_condition);
        }
        let sinv = if nc == 0 {
            DMatrix::zeros(0, 0)
        } else {
            let Ok(llt) = to_faer(&reduced.s).llt(Side::Lower) else { return (None, inverse_condition) };
            let inv = llt.inverse();
            DMatrix::from_fn(nc, nc, |i, j| inv[(i, j)])
        };
        let elim = (0..self.d.len())
            .map(|e| {
                let w = self.bt[e].transpose() * &reduced.dinv[e];
                (&reduced.dinv[e] + w.transpose() * &sinv * &w) * sigma2
            })
            .collect();
        (Some((sinv * sigma2, elim)), inverse_condition)
    }
}

/// Covariance of the kept parameters and the marginal covariance of each eliminated block.
pub(crate) type CovarianceBlocks = (DMatrix<f64>, Vec<DMatrix<f64>>);

struct Reduced {
    s: DMatrix<f64>,
    rhs: DVector<f64>,
    dinv: Vec<DMatrix<f64>>,
}

fn to_faer(m: &DMatrix<f64>) -> Mat<f64> {
    Mat::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

/// Smallest over largest eigenvalue of `m` scaled to a unit diagonal (0 when not positive).
fn scaled_inverse_condition(m: &DMatrix<f64>) -> f64 {
    let n = m.nrows();
    if n == 0 {
        return f64::INFINITY;
    }
    let d: Vec<f64> = (0..n).map(|i| 1.0 / m[(i, i)].max(1e-300).sqrt()).collect();
    let ms = Mat::<f64>::from_fn(n, n, |i, j| m[(i, j)] * d[i] * d[j]);
    let Ok(eig) = ms.self_adjoint_eigenvalues(Side::Lower) else { return 0.0 };
    let (mn, mx) = eig.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
    if mx > 0.0 {
        (mn / mx).max(0.0)
    } else {
        0.0
    }
}
