//! The weighted normal equations of a Gauss-Newton step over edge samples in two views:
//! `JᵀWJ δ = -JᵀWr`, with the weighted RMS residual `sqrt(Σ w r² / Σ w)` and the samples each
//! view gave (the rim and two-view fits' accumulator).

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

#[cfg(test)]
mod tests {
    use super::*;

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
