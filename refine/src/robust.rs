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
}
