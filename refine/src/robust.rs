//! Robust loss (Tukey biweight) and scale estimation.
//!
//! `ρ(r) = c²/6 (1 - (1 - (r/c)²)³)` for `|r| < c`, `c²/6` beyond; IRLS weight
//! `w(r) = (1 - (r/c)²)²` inside, 0 beyond. Scale `σ = 1.4826 median|r|` (MAD about zero).

/// Tukey cost of residual `r` with threshold `c`.
#[inline]
pub fn tukey_rho(r: f64, c: f64) -> f64 {
    let c2 = c * c / 6.0;
    if r.abs() >= c {
        return c2;
    }
    let u = 1.0 - (r / c) * (r / c);
    c2 * (1.0 - u * u * u)
}

/// Tukey IRLS weight of residual `r` with threshold `c`.
#[inline]
pub fn tukey_weight(r: f64, c: f64) -> f64 {
    if r.abs() >= c {
        return 0.0;
    }
    let u = 1.0 - (r / c) * (r / c);
    u * u
}

/// The weighted normal equations of a Gauss-Newton step over the edge samples of two views:
/// `JᵀWJ`, `JᵀWr` (`D` parameters), `Σ w r²`, `Σ w`, and how many samples each view gave.
#[derive(Clone, Debug)]
pub(crate) struct TwoViewNormalEquations<const D: usize> {
    /// `Σ w j jᵀ`.
    pub jtj: nalgebra::SMatrix<f64, D, D>,
    /// `Σ w r j`.
    pub jtr: nalgebra::SVector<f64, D>,
    wrr: f64,
    wsum: f64,
    /// Samples of the first view, of the second.
    pub counts: (usize, usize),
}

impl<const D: usize> TwoViewNormalEquations<D> {
    /// Empty sums.
    pub fn new() -> Self {
        TwoViewNormalEquations { jtj: nalgebra::SMatrix::zeros(), jtr: nalgebra::SVector::zeros(), wrr: 0.0, wsum: 0.0, counts: (0, 0) }
    }

    /// Adds a sample of view `view` (0 or 1): Jacobian row `j`, residual `r` (px), weight `w`.
    pub fn add(&mut self, view: usize, j: &nalgebra::SVector<f64, D>, r: f64, w: f64) {
        if view == 0 {
            self.counts.0 += 1;
        } else {
            self.counts.1 += 1;
        }
        self.jtj += j * j.transpose() * w;
        self.jtr += j * (w * r);
        self.wrr += w * r * r;
        self.wsum += w;
    }

    /// The weighted RMS residual `sqrt(Σ w r² / Σ w)` (px).
    pub fn rms(&self) -> f64 {
        (self.wrr / self.wsum.max(1e-9)).sqrt()
    }
}

/// `1.4826 · median(|r|)`, or `None` for an empty slice. Reorders a scratch copy.
pub fn mad_scale(r: &[f64], scratch: &mut Vec<f64>) -> Option<f64> {
    if r.is_empty() {
        return None;
    }
    scratch.clear();
    scratch.extend(r.iter().map(|v| v.abs()));
    let mid = scratch.len() / 2;
    let (_, m, _) = scratch.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    Some(1.4826 * *m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tukey_is_quadratic_near_zero_and_flat_beyond() {
        let c = 3.0;
        assert!((tukey_rho(0.01, c) - 0.5 * 0.01 * 0.01).abs() < 1e-8);
        assert_eq!(tukey_rho(5.0, c), tukey_rho(-3.0, c));
        assert_eq!(tukey_weight(0.0, c), 1.0);
        assert_eq!(tukey_weight(3.5, c), 0.0);
        // Weight is ρ'(r)/r: check by finite differences.
        let (r, h) = (1.2, 1e-6);
        let d = (tukey_rho(r + h, c) - tukey_rho(r - h, c)) / (2.0 * h);
        assert!((d / r - tukey_weight(r, c)).abs() < 1e-6);
        let mut s = Vec::new();
        let sc = mad_scale(&[1.0, -2.0, 3.0, -100.0, 0.5], &mut s).unwrap();
        assert!((sc - 1.4826 * 2.0).abs() < 1e-12);
    }

    #[test]
    fn the_normal_equations_solve_a_weighted_line_fit() {
        // y = 2 x + 1 sampled in two views, one outlier weighted out: the Gauss-Newton step
        // from (0, 0) lands on the line, and the sums are the textbook ones.
        let mut eq = TwoViewNormalEquations::<2>::new();
        let samples = [(0, 0.0, 1.0, 1.0), (0, 1.0, 3.0, 1.0), (1, 2.0, 5.0, 2.0), (1, 3.0, 40.0, 0.0)];
        for (view, x, y, w) in samples {
            // Residual of the model p0 x + p1 at p = 0: -y; its Jacobian row (x, 1).
            eq.add(view, &nalgebra::Vector2::new(x, 1.0), -y, w);
        }
        assert_eq!(eq.counts, (2, 2));
        let step = eq.jtj.lu().solve(&(-eq.jtr)).unwrap();
        assert!((step - nalgebra::Vector2::new(2.0, 1.0)).amax() < 1e-12, "{step}");
        let expected_rms = ((1.0 + 9.0 + 2.0 * 25.0) / 4.0f64).sqrt();
        assert!((eq.rms() - expected_rms).abs() < 1e-12);
    }
}
