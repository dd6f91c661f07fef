//! A small Levenberg-Marquardt solver over parameter blocks, with the normal equations solved
//! by the Schur complement (faer) as bundle adjusters do.
//!
//! The problem is `min_x Σ_k ||r_k(x_{b(k)})||²` where residual block `k` depends on a few
//! parameter blocks `b(k)`. Jacobians come from the residual's own analytic function when it has
//! one ([`Problem::add_residual_with_jacobian`]), else from central differences per block (step
//! `1e-6·max(1,|x|)` for plain blocks, `1e-7` rad / m on the tangent space of pose blocks).
//! They are accumulated into the block normal equations `(JᵀJ + λ·diag(JᵀJ)) δ = −Jᵀr`; the
//! blocks that no two-eliminated-block residual links (per-view poses) are eliminated and the
//! reduced system is solved by Cholesky ([`schur`]). Pose blocks are `[ω (rotation vector,
//! rad), t (m)]` updated on the left: `R ← exp(δω)·R`, `t ← t + δt`. The covariance of the free
//! parameters is `σ²·(JᵀJ)⁻¹` with `σ² = Σr²/(m − n)`, by blocks from the same factorization.

mod schur;

use crate::error::CalibError;
use nalgebra::{DMatrix, DVector, Rotation3, Vector3};
use rayon::prelude::*;
use schur::{BlockNormal, Layout, Place, Segment};

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

/// Residual and Jacobian function: like [`ResidualFn`], and also writes the Jacobian row-major
/// (`len` rows, one column per block parameter in the order of the blocks, fixed blocks
/// included; for pose blocks the derivative along the left update `[δω, δt]`).
pub type JacobianFn<'a> = Box<dyn Fn(&[&[f64]], &mut [f64], &mut [f64]) -> bool + Sync + 'a>;

/// One residual block.
pub struct ResidualBlock<'a> {
    /// Indices of the parameter blocks it reads.
    pub blocks: Vec<usize>,
    /// Number of residuals.
    pub len: usize,
    /// The function.
    pub f: ResidualFn<'a>,
    /// Its analytic Jacobian, when given (else numeric).
    pub jacobian: Option<JacobianFn<'a>>,
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

/// Covariance of the free parameters, by blocks (`σ²·(JᵀJ)⁻¹`).
#[derive(Clone, Debug)]
pub struct Covariance {
    place: Vec<Place>,
    sizes: Vec<usize>,
    kept: DMatrix<f64>,
    eliminated: Vec<DMatrix<f64>>,
}

impl Covariance {
    /// The marginal covariance of block `b` (its own parameters; tangent space for poses), or
    /// `None` for a fixed block.
    pub fn block(&self, b: usize) -> Option<DMatrix<f64>> {
        match self.place[b] {
            Place::Fixed => None,
            Place::Kept(o) => Some(self.kept.view((o, o), (self.sizes[b], self.sizes[b])).into_owned()),
            Place::Eliminated(e) => Some(self.eliminated[e].clone()),
        }
    }
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
    /// Number of parameters in the reduced (Schur complement) system.
    pub reduced_params: usize,
    /// `σ²·(JᵀJ)⁻¹` by blocks, when `JᵀJ` is invertible.
    pub covariance: Option<Covariance>,
    /// Smallest / largest eigenvalue after column scaling (1/condition), the smallest over the
    /// Schur complement and the eliminated blocks (`JᵀJ` is positive definite exactly when all
    /// of these are).
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

    /// Adds a residual block (numeric Jacobian).
    pub fn add_residual(&mut self, blocks: Vec<usize>, len: usize, f: ResidualFn<'a>) {
        self.residuals.push(ResidualBlock { blocks, len, f, jacobian: None, active: true });
    }

    /// Adds a residual block with its analytic Jacobian `jac` (see [`JacobianFn`]); `f` must
    /// compute the same residuals (it is used where no Jacobian is needed).
    pub fn add_residual_with_jacobian(&mut self, blocks: Vec<usize>, len: usize, f: ResidualFn<'a>, jac: JacobianFn<'a>) {
        self.residuals.push(ResidualBlock { blocks, len, f, jacobian: Some(jac), active: true });
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

    fn layout(&self) -> Layout {
        let sizes: Vec<usize> = self.params.iter().map(|p| p.len()).collect();
        let reads: Vec<Option<&[usize]>> = self.residuals.iter().map(|r| r.active.then_some(r.blocks.as_slice())).collect();
        Layout::new(&sizes, &self.fixed, &reads)
    }

    /// Builds the block normal equations at the current parameters: one rayon task per
    /// eliminated block (its residuals), plus chunks of the residuals that read none.
    fn normal_equations(&self, layout: &Layout) -> Result<BlockNormal, CalibError> {
        let mut tasks: Vec<(Option<usize>, &[usize])> = layout.groups.iter().enumerate().map(|(e, g)| (Some(e), g.as_slice())).collect();
        tasks.extend(layout.ungrouped.chunks(256).map(|c| (None, c)));
        let parts = tasks
            .par_iter()
            .map(|(group, ks)| {
                let mut acc = BlockNormal::zeros_for(layout, |e| Some(e) == *group);
                let mut scratch = JacobianScratch::default();
                for &k in ks.iter() {
                    self.accumulate(&self.residuals[k], layout, &mut acc, &mut scratch)?;
                }
                Ok(acc)
            })
            .collect::<Result<Vec<_>, CalibError>>()?;
        let mut total = BlockNormal::zeros(layout);
        for p in &parts {
            total.merge(p);
        }
        total.symmetrize();
        Ok(total)
    }

    /// Computes one residual block's residuals and the Jacobian columns of its free blocks
    /// (row-major into `s.jac`, column runs in `s.segs`).
    fn jacobian_columns(&self, rb: &ResidualBlock, layout: &Layout, s: &mut JacobianScratch) -> Result<(), CalibError> {
        let m = rb.len;
        s.r.clear();
        s.r.resize(m, 0.0);
        s.segs.clear();
        for &b in &rb.blocks {
            if layout.place[b] != Place::Fixed {
                s.segs.push(Segment { place: layout.place[b], len: self.params[b].len() });
            }
        }
        let ncols: usize = s.segs.iter().map(|g| g.len).sum();
        s.jac.clear();
        s.jac.resize(m * ncols, 0.0);
        let xs: Vec<&[f64]> = rb.blocks.iter().map(|&b| self.params[b].as_slice()).collect();
        if let Some(jf) = &rb.jacobian {
            let total: usize = rb.blocks.iter().map(|&b| self.params[b].len()).sum();
            s.full.clear();
            s.full.resize(m * total, 0.0);
            if !jf(&xs, &mut s.r, &mut s.full) {
                return Err(CalibError::Optimization("a residual became undefined (point behind a camera?)".into()));
            }
            let (mut c0, mut c1) = (0, 0);
            for &b in &rb.blocks {
                let len = self.params[b].len();
                if layout.place[b] != Place::Fixed {
                    for row in 0..m {
                        s.jac[row * ncols + c1..row * ncols + c1 + len].copy_from_slice(&s.full[row * total + c0..row * total + c0 + len]);
                    }
                    c1 += len;
                }
                c0 += len;
            }
            return Ok(());
        }
        if !(rb.f)(&xs, &mut s.r) {
            return Err(CalibError::Optimization("a residual became undefined (point behind a camera?)".into()));
        }
        let mut scratch: Vec<Vec<f64>> = rb.blocks.iter().map(|&b| self.params[b].clone()).collect();
        let (mut rp, mut rm) = (vec![0.0; m], vec![0.0; m]);
        let mut c1 = 0;
        for (slot, &b) in rb.blocks.iter().enumerate() {
            if layout.place[b] == Place::Fixed {
                continue;
            }
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
                for k in 0..m {
                    s.jac[k * ncols + c1] = (rp[k] - rm[k]) / (2.0 * step);
                }
                c1 += 1;
            }
        }
        Ok(())
    }

    /// Adds one residual block's `JᵀJ`, `Jᵀr` and `Σr²`.
    fn accumulate(&self, rb: &ResidualBlock, layout: &Layout, acc: &mut BlockNormal, s: &mut JacobianScratch) -> Result<(), CalibError> {
        self.jacobian_columns(rb, layout, s)?;
        acc.add(&s.r, &s.segs, &s.jac);
        Ok(())
    }

    /// Applies a solution of the block system to the current parameters.
    fn updated(&self, layout: &Layout, dc: &DVector<f64>, de: &[DVector<f64>]) -> Vec<Vec<f64>> {
        let mut trial = self.params.clone();
        for (b, t) in trial.iter_mut().enumerate() {
            let x = &self.params[b];
            match layout.place[b] {
                Place::Fixed => {}
                Place::Kept(o) => plus(self.kinds[b], x, &dc.as_slice()[o..o + x.len()], t),
                Place::Eliminated(e) => plus(self.kinds[b], x, de[e].as_slice(), t),
            }
        }
        trial
    }

    /// Runs Levenberg-Marquardt for at most `max_iterations`.
    pub fn solve(&mut self, max_iterations: usize) -> Result<Solution, CalibError> {
        let n: usize = (0..self.params.len()).filter(|&b| !self.fixed[b]).map(|b| self.params[b].len()).sum();
        let m: usize = self.residuals.iter().filter(|r| r.active).map(|r| r.len).sum();
        if m < n {
            return Err(CalibError::TooFew(format!("{m} residuals for {n} unknowns")));
        }
        let layout = self.layout();
        let initial_cost = self.cost_at(&self.params).ok_or_else(|| CalibError::Optimization("residuals undefined at the initial estimate".into()))?;
        let mut lambda = 1e-3;
        let mut iterations = 0;
        let mut normal = self.normal_equations(&layout)?;
        for _ in 0..max_iterations {
            iterations += 1;
            let mut improved = false;
            for _ in 0..12 {
                let Some((dc, de)) = normal.solve(lambda) else {
                    lambda *= 10.0;
                    continue;
                };
                let trial = self.updated(&layout, &dc, &de);
                match self.cost_at(&trial) {
                    Some(c) if c < normal.cost => {
                        let rel = (normal.cost - c) / normal.cost.max(1e-300);
                        let step = (dc.norm_squared() + de.iter().map(|v| v.norm_squared()).sum::<f64>()).sqrt();
                        self.params = trial;
                        lambda = (lambda / 3.0).max(1e-12);
                        improved = true;
                        normal = self.normal_equations(&layout)?;
                        if rel < 1e-10 || step < 1e-12 {
                            return Ok(self.finish(&layout, &normal, initial_cost, iterations, m, n));
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
        Ok(self.finish(&layout, &normal, initial_cost, iterations, m, n))
    }

    fn finish(&self, layout: &Layout, normal: &BlockNormal, initial_cost: f64, iterations: usize, m: usize, n: usize) -> Solution {
        let sigma2 = if m > n { normal.cost / (m - n) as f64 } else { f64::NAN };
        let (cov, inverse_condition) = normal.covariance(sigma2);
        let covariance = cov.map(|(kept, eliminated)| Covariance { place: layout.place.clone(), sizes: self.params.iter().map(|p| p.len()).collect(), kept, eliminated });
        Solution { cost: normal.cost, initial_cost, iterations, residual_count: m, free_params: n, reduced_params: layout.kept_len, covariance, inverse_condition }
    }
}

/// Buffers reused across residual blocks.
#[derive(Default)]
struct JacobianScratch {
    r: Vec<f64>,
    segs: Vec<Segment>,
    jac: Vec<f64>,
    full: Vec<f64>,
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
        let cov = s.covariance.unwrap().block(b).unwrap();
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

    /// A small two-camera problem of the calibration's shape: per-camera pinhole intrinsics
    /// `[f, cx, cy]`, a free `T_cam2_cam1`, four board poses, a 3x3 grid per view, noisy pixels.
    fn small_rig_problem() -> Problem<'static> {
        let mut p = Problem::new();
        let intr = [p.add_block(vec![500.0, 320.0, 240.0], BlockKind::Euclidean, false), p.add_block(vec![510.0, 318.0, 236.0], BlockKind::Euclidean, false)];
        let ext = [p.add_block(vec![0.0; 6], BlockKind::Pose, true), p.add_block(vec![0.01, -0.02, 0.005, -0.1, 0.002, 0.001], BlockKind::Pose, false)];
        let mut k = 0usize;
        for v in 0..4 {
            let f = v as f64;
            let pose = p.add_block(vec![0.1 * f - 0.15, 0.2 - 0.07 * f, 0.05 * f, 0.02 * f - 0.03, 0.01 - 0.01 * f, 1.0 + 0.1 * f], BlockKind::Pose, false);
            for c in 0..2 {
                for g in 0..9 {
                    let x = nalgebra::Vector3::new(0.05 * (g % 3) as f64, 0.05 * (g / 3) as f64, 0.0);
                    k += 1;
                    // Observations: a fixed pattern not consistent with any parameters (nonzero residuals).
                    let u = (300.0 + 40.0 * (g % 3) as f64 + (k * 7 % 11) as f64 * 0.3, 220.0 + 40.0 * (g / 3) as f64 - (k * 5 % 13) as f64 * 0.2);
                    p.add_residual(
                        vec![intr[c], ext[c], pose],
                        2,
                        Box::new(move |b, r| {
                            let rp = Rotation3::new(Vector3::new(b[2][0], b[2][1], b[2][2])) * x + Vector3::new(b[2][3], b[2][4], b[2][5]);
                            let pc = Rotation3::new(Vector3::new(b[1][0], b[1][1], b[1][2])) * rp + Vector3::new(b[1][3], b[1][4], b[1][5]);
                            r[0] = b[0][0] * pc.x / pc.z + b[0][1] - u.0;
                            r[1] = b[0][0] * pc.y / pc.z + b[0][2] - u.1;
                            true
                        }),
                    );
                }
            }
        }
        p
    }

    /// Dense `JᵀJ` and `Jᵀr` over the free parameters in block order, from a whole-problem
    /// numeric Jacobian (same steps as the solver's), with no block structure.
    fn dense_normal(p: &Problem) -> (DMatrix<f64>, DVector<f64>, Vec<Option<usize>>) {
        let all = |params: &[Vec<f64>]| -> Vec<f64> {
            p.residuals
                .iter()
                .flat_map(|rb| {
                    let xs: Vec<&[f64]> = rb.blocks.iter().map(|&b| params[b].as_slice()).collect();
                    let mut r = vec![0.0; rb.len];
                    assert!((rb.f)(&xs, &mut r));
                    r
                })
                .collect()
        };
        let r0 = DVector::from_vec(all(&p.params));
        let mut offsets = vec![None; p.params.len()];
        let mut n = 0;
        for (b, offset) in offsets.iter_mut().enumerate() {
            if !p.fixed[b] {
                *offset = Some(n);
                n += p.params[b].len();
            }
        }
        let mut j = DMatrix::zeros(r0.len(), n);
        for b in 0..p.params.len() {
            let Some(off) = offsets[b] else { continue };
            for i in 0..p.params[b].len() {
                let step = match p.kinds[b] {
                    BlockKind::Euclidean => 1e-6 * p.params[b][i].abs().max(1.0),
                    BlockKind::Pose => 1e-7,
                };
                let eval = |s: f64| {
                    let mut params = p.params.clone();
                    let mut d = vec![0.0; params[b].len()];
                    d[i] = s;
                    plus(p.kinds[b], &p.params[b], &d, &mut params[b]);
                    DVector::from_vec(all(&params))
                };
                let col = (eval(step) - eval(-step)) / (2.0 * step);
                j.set_column(off + i, &col);
            }
        }
        (j.transpose() * &j, j.transpose() * r0, offsets)
    }

    #[test]
    fn schur_solve_agrees_with_a_dense_solve_of_the_full_normal_equations() {
        let p = small_rig_problem();
        let layout = p.layout();
        assert_eq!(layout.kept_len, 3 + 3 + 6, "intrinsics and the free extrinsic are kept, the four board poses eliminated");
        assert_eq!(layout.elim_len, vec![6; 4]);
        let normal = p.normal_equations(&layout).unwrap();
        let (h, g, offsets) = dense_normal(&p);
        let rel = |a: &DVector<f64>, b: &DVector<f64>| (a - b).norm() / b.norm();
        for lambda in [0.0, 1e-3, 10.0] {
            let (dc, de) = normal.solve(lambda).unwrap();
            let mut damped = h.clone();
            for i in 0..h.nrows() {
                damped[(i, i)] += lambda * h[(i, i)].max(1e-12);
            }
            let dense = damped.cholesky().unwrap().solve(&(-&g));
            let mut schur = DVector::zeros(h.nrows());
            for (b, place) in layout.place.iter().enumerate() {
                let Some(off) = offsets[b] else { continue };
                let len = p.params[b].len();
                match *place {
                    Place::Kept(o) => schur.rows_mut(off, len).copy_from(&dc.rows(o, len)),
                    Place::Eliminated(e) => schur.rows_mut(off, len).copy_from(&de[e]),
                    Place::Fixed => unreachable!(),
                }
            }
            assert!(rel(&schur, &dense) < 1e-9, "lambda {lambda}: relative difference {:.2e}", rel(&schur, &dense));
        }
        // Covariance blocks against the dense inverse.
        let inv = h.clone().cholesky().unwrap().inverse();
        let (cov, inverse_condition) = normal.covariance(1.0);
        let (kept, elim) = cov.unwrap();
        assert!(inverse_condition > 0.0);
        for (b, place) in layout.place.iter().enumerate() {
            let Some(off) = offsets[b] else { continue };
            let len = p.params[b].len();
            let dense = inv.view((off, off), (len, len)).into_owned();
            let schur = match *place {
                Place::Kept(o) => kept.view((o, o), (len, len)).into_owned(),
                Place::Eliminated(e) => elim[e].clone(),
                Place::Fixed => unreachable!(),
            };
            let d = (&schur - &dense).norm() / dense.norm();
            assert!(d < 1e-9, "block {b}: covariance relative difference {d:.2e}");
        }
    }
}
