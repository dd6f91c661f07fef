//! A small Levenberg-Marquardt solver over parameter blocks with numeric Jacobians.
//!
//! The problem is `min_x Σ_k ||r_k(x_{b(k)})||²` where residual block `k` depends on a few
//! parameter blocks `b(k)`. Jacobians are central differences per block (step `1e-6·max(1,|x|)`
//! for plain blocks, `1e-7` rad / m on the tangent space of pose blocks), accumulated into the
//! dense normal equations `(JᵀJ + λ·diag(JᵀJ)) δ = −Jᵀr`, solved by Cholesky. Pose blocks are
//! `[ω (rotation vector, rad), t (m)]` updated on the left: `R ← exp(δω)·R`, `t ← t + δt`.
//! The covariance of the free parameters is `σ²·(JᵀJ)⁻¹` with `σ² = Σr²/(m − n)`.

use crate::error::CalibError;
use nalgebra::{DMatrix, DVector, Rotation3, Vector3};
use rayon::prelude::*;

/// How a parameter block is updated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlockKind {
    /// Plain vector, additive updates.
    Euclidean,
    /// `[ωx, ωy, ωz, tx, ty, tz]`, left-multiplicative rotation updates.
    Pose,
}

/// Residual function: reads the blocks it depends on (in the order given), writes residuals,
/// returns `false` when the residual is undefined there (e.g. point behind the camera).
pub type ResidualFn<'a> = Box<dyn Fn(&[&[f64]], &mut [f64]) -> bool + Sync + 'a>;

/// One residual block.
pub struct ResidualBlock<'a> {
    /// Indices of the parameter blocks it reads.
    pub blocks: Vec<usize>,
    /// Number of residuals.
    pub len: usize,
    /// The function.
    pub f: ResidualFn<'a>,
    /// Inactive blocks (rejected outliers) are ignored.
    pub active: bool,
}

/// A least-squares problem.
pub struct Problem<'a> {
    /// Parameter values.
    pub params: Vec<Vec<f64>>,
    /// Kind of each block.
    pub kinds: Vec<BlockKind>,
    /// Held-constant blocks.
    pub fixed: Vec<bool>,
    /// Residual blocks.
    pub residuals: Vec<ResidualBlock<'a>>,
}

/// Outcome of [`Problem::solve`].
#[derive(Clone, Debug)]
pub struct Solution {
    /// Final `Σ r²`.
    pub cost: f64,
    /// Initial `Σ r²`.
    pub initial_cost: f64,
    /// Iterations run.
    pub iterations: usize,
    /// Number of active residuals.
    pub residual_count: usize,
    /// Number of free parameters.
    pub free_params: usize,
    /// Column offset of each free block in the normal matrix (`None` for fixed blocks).
    pub offsets: Vec<Option<usize>>,
    /// `σ²·(JᵀJ)⁻¹` over the free parameters, when `JᵀJ` is invertible.
    pub covariance: Option<DMatrix<f64>>,
    /// Smallest / largest eigenvalue of `JᵀJ` after column scaling (1/condition).
    pub inverse_condition: f64,
}

/// Applies the update `delta` to a block.
pub fn plus(kind: BlockKind, x: &[f64], delta: &[f64], out: &mut [f64]) {
    match kind {
        BlockKind::Euclidean => {
            for i in 0..x.len() {
                out[i] = x[i] + delta[i];
            }
        }
        BlockKind::Pose => {
            let r = Rotation3::new(Vector3::new(delta[0], delta[1], delta[2])) * Rotation3::new(Vector3::new(x[0], x[1], x[2]));
            let w = r.scaled_axis();
            out[..3].copy_from_slice(w.as_slice());
            for i in 3..6 {
                out[i] = x[i] + delta[i];
            }
        }
    }
}

impl<'a> Problem<'a> {
    /// An empty problem.
    pub fn new() -> Self {
        Problem { params: Vec::new(), kinds: Vec::new(), fixed: Vec::new(), residuals: Vec::new() }
    }

    /// Adds a parameter block and returns its index.
    pub fn add_block(&mut self, x: Vec<f64>, kind: BlockKind, fixed: bool) -> usize {
        if kind == BlockKind::Pose {
            assert_eq!(x.len(), 6, "pose blocks have 6 parameters");
        }
        self.params.push(x);
        self.kinds.push(kind);
        self.fixed.push(fixed);
        self.params.len() - 1
    }

    /// Adds a residual block.
    pub fn add_residual(&mut self, blocks: Vec<usize>, len: usize, f: ResidualFn<'a>) {
        self.residuals.push(ResidualBlock { blocks, len, f, active: true });
    }

    /// Residuals of block `k` at the current parameters (`None` when undefined).
    pub fn residual(&self, k: usize) -> Option<Vec<f64>> {
        let rb = &self.residuals[k];
        let xs: Vec<&[f64]> = rb.blocks.iter().map(|&b| self.params[b].as_slice()).collect();
        let mut r = vec![0.0; rb.len];
        (rb.f)(&xs, &mut r).then_some(r)
    }

    fn cost_at(&self, params: &[Vec<f64>]) -> Option<f64> {
        let c = self
            .residuals
            .par_iter()
            .filter(|r| r.active)
            .map(|rb| {
                let xs: Vec<&[f64]> = rb.blocks.iter().map(|&b| params[b].as_slice()).collect();
                let mut r = vec![0.0; rb.len];
                (rb.f)(&xs, &mut r).then(|| r.iter().map(|v| v * v).sum::<f64>())
            })
            .try_reduce(|| 0.0, |a, b| Some(a + b))?;
        c.is_finite().then_some(c)
    }

    /// Builds `JᵀJ` and `Jᵀr` at the current parameters (residual blocks split across rayon
    /// workers, each with its own accumulator).
    fn normal_equations(&self, offsets: &[Option<usize>], n: usize) -> Result<(DMatrix<f64>, DVector<f64>, f64), CalibError> {
        let active: Vec<&ResidualBlock> = self.residuals.iter().filter(|r| r.active).collect();
        let chunk = (active.len() / (4 * rayon::current_num_threads().max(1))).max(256);
        active
            .par_chunks(chunk)
            .map(|blocks| {
                let mut h = DMatrix::<f64>::zeros(n, n);
                let mut g = DVector::<f64>::zeros(n);
                let mut cost = 0.0;
                for rb in blocks {
                    cost += self.accumulate(rb, offsets, &mut h, &mut g)?;
                }
                Ok((h, g, cost))
            })
            .try_reduce(|| (DMatrix::zeros(n, n), DVector::zeros(n), 0.0), |a, b| Ok((a.0 + b.0, a.1 + b.1, a.2 + b.2)))
    }

    /// Adds one residual block's `JᵀJ` and `Jᵀr` (numeric Jacobian); returns its `Σr²`.
    fn accumulate(&self, rb: &ResidualBlock, offsets: &[Option<usize>], h: &mut DMatrix<f64>, g: &mut DVector<f64>) -> Result<f64, CalibError> {
        let mut scratch: Vec<Vec<f64>> = rb.blocks.iter().map(|&b| self.params[b].clone()).collect();
        let m = rb.len;
        let mut r0 = vec![0.0; m];
        {
            let xs: Vec<&[f64]> = scratch.iter().map(|v| v.as_slice()).collect();
            if !(rb.f)(&xs, &mut r0) {
                return Err(CalibError::Optimization("a residual became undefined (point behind a camera?)".into()));
            }
        }
        let cost = r0.iter().map(|v| v * v).sum::<f64>();
        // Columns of this block's Jacobian: (global column, derivative vector).
        let mut cols: Vec<(usize, Vec<f64>)> = Vec::new();
        let (mut rp, mut rm) = (vec![0.0; m], vec![0.0; m]);
        for (slot, &b) in rb.blocks.iter().enumerate() {
            let Some(off) = offsets[b] else { continue };
            let kind = self.kinds[b];
            let x = self.params[b].clone();
            let mut d = vec![0.0; x.len()];
            for i in 0..x.len() {
                let step = match kind {
                    BlockKind::Euclidean => 1e-6 * x[i].abs().max(1.0),
                    BlockKind::Pose => 1e-7,
                };
                d[i] = step;
                plus(kind, &x, &d, &mut scratch[slot]);
                let okp = (rb.f)(&scratch.iter().map(|v| v.as_slice()).collect::<Vec<_>>(), &mut rp);
                d[i] = -step;
                plus(kind, &x, &d, &mut scratch[slot]);
                let okm = (rb.f)(&scratch.iter().map(|v| v.as_slice()).collect::<Vec<_>>(), &mut rm);
                d[i] = 0.0;
                scratch[slot].copy_from_slice(&x);
                if !(okp && okm) {
                    return Err(CalibError::Optimization("a residual is undefined next to the current estimate".into()));
                }
                cols.push((off + i, (0..m).map(|k| (rp[k] - rm[k]) / (2.0 * step)).collect()));
            }
        }
        for (a, (ca, ja)) in cols.iter().enumerate() {
            g[*ca] += ja.iter().zip(&r0).map(|(x, y)| x * y).sum::<f64>();
            for (cb, jb) in cols[a..].iter() {
                let v: f64 = ja.iter().zip(jb).map(|(x, y)| x * y).sum();
                h[(*ca, *cb)] += v;
                if ca != cb {
                    h[(*cb, *ca)] += v;
                }
            }
        }
        Ok(cost)
    }

    /// Runs Levenberg-Marquardt for at most `max_iterations`.
    pub fn solve(&mut self, max_iterations: usize) -> Result<Solution, CalibError> {
        let mut offsets = vec![None; self.params.len()];
        let mut n = 0;
        for (b, offset) in offsets.iter_mut().enumerate() {
            if !self.fixed[b] {
                *offset = Some(n);
                n += self.params[b].len();
            }
        }
        let m: usize = self.residuals.iter().filter(|r| r.active).map(|r| r.len).sum();
        if m < n {
            return Err(CalibError::TooFew(format!("{m} residuals for {n} unknowns")));
        }
        let initial_cost = self.cost_at(&self.params).ok_or_else(|| CalibError::Optimization("residuals undefined at the initial estimate".into()))?;
        let mut lambda = 1e-3;
        let mut iterations = 0;
        let (mut h, mut g, mut cost) = self.normal_equations(&offsets, n)?;
        for _ in 0..max_iterations {
            iterations += 1;
            let mut improved = false;
            for _ in 0..12 {
                let mut a = h.clone();
                for i in 0..n {
                    a[(i, i)] += lambda * h[(i, i)].max(1e-12);
                }
                let Some(chol) = a.cholesky() else {
                    lambda *= 10.0;
                    continue;
                };
                let delta = chol.solve(&(-&g));
                let mut trial = self.params.clone();
                for b in 0..trial.len() {
                    if let Some(off) = offsets[b] {
                        let x = self.params[b].clone();
                        plus(self.kinds[b], &x, &delta.as_slice()[off..off + x.len()], &mut trial[b]);
                    }
                }
                match self.cost_at(&trial) {
                    Some(c) if c < cost => {
                        let rel = (cost - c) / cost.max(1e-300);
                        self.params = trial;
                        lambda = (lambda / 3.0).max(1e-12);
                        improved = true;
                        let (h2, g2, c2) = self.normal_equations(&offsets, n)?;
                        h = h2;
                        g = g2;
                        cost = c2;
                        if rel < 1e-10 || delta.norm() < 1e-12 {
                            return Ok(self.finish(h, cost, initial_cost, iterations, m, n, offsets));
                        }
                        break;
                    }
                    _ => lambda *= 10.0,
                }
            }
            if !improved {
                break;
            }
        }
        Ok(self.finish(h, cost, initial_cost, iterations, m, n, offsets))
    }

    #[allow(clippy::too_many_arguments)]
    fn finish(&self, h: DMatrix<f64>, cost: f64, initial_cost: f64, iterations: usize, m: usize, n: usize, offsets: Vec<Option<usize>>) -> Solution {
        // Condition of the column-scaled normal matrix.
        let d: Vec<f64> = (0..n).map(|i| 1.0 / h[(i, i)].max(1e-300).sqrt()).collect();
        let hs = DMatrix::from_fn(n, n, |i, j| h[(i, j)] * d[i] * d[j]);
        let eig = hs.clone().symmetric_eigenvalues();
        let (mn, mx) = eig.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
        let inverse_condition = if mx > 0.0 { (mn / mx).max(0.0) } else { 0.0 };
        let sigma2 = if m > n { cost / (m - n) as f64 } else { f64::NAN };
        let covariance = if inverse_condition > 1e-14 {
            hs.cholesky().map(|c| {
                let inv = c.inverse();
                DMatrix::from_fn(n, n, |i, j| inv[(i, j)] * d[i] * d[j] * sigma2)
            })
        } else {
            None
        };
        Solution { cost, initial_cost, iterations, residual_count: m, free_params: n, offsets, covariance, inverse_condition }
    }
}

impl Default for Problem<'_> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_an_exponential_and_reports_covariance() {
        // y = a·exp(b·x) with a = 2, b = -0.7, plus small deterministic perturbations.
        let xs: Vec<f64> = (0..30).map(|i| i as f64 * 0.1).collect();
        let ys: Vec<f64> = xs.iter().enumerate().map(|(i, x)| 2.0 * (-0.7 * x).exp() + 1e-3 * ((i * 7 % 5) as f64 - 2.0)).collect();
        let mut p = Problem::new();
        let b = p.add_block(vec![1.0, 0.0], BlockKind::Euclidean, false);
        for (x, y) in xs.iter().zip(&ys) {
            let (x, y) = (*x, *y);
            p.add_residual(
                vec![b],
                1,
                Box::new(move |v, r| {
                    r[0] = v[0][0] * (v[0][1] * x).exp() - y;
                    true
                }),
            );
        }
        let s = p.solve(100).unwrap();
        assert!((p.params[b][0] - 2.0).abs() < 5e-3 && (p.params[b][1] + 0.7).abs() < 5e-3, "{:?}", p.params[b]);
        assert!(s.cost < s.initial_cost * 1e-4);
        let cov = s.covariance.unwrap();
        assert!(cov[(0, 0)] > 0.0 && cov[(0, 0)].sqrt() < 1e-2);
    }

    #[test]
    fn pose_block_rotates_on_the_left() {
        let x = [0.1, -0.2, 0.3, 1.0, 2.0, 3.0];
        let mut out = [0.0; 6];
        plus(BlockKind::Pose, &x, &[0.0, 0.0, 0.5, 0.0, 0.0, 1.0], &mut out);
        let r = Rotation3::new(Vector3::new(out[0], out[1], out[2]));
        let expect = Rotation3::new(Vector3::new(0.0, 0.0, 0.5)) * Rotation3::new(Vector3::new(0.1, -0.2, 0.3));
        assert!(r.angle_to(&expect) < 1e-12 && out[5] == 4.0);
    }
}
