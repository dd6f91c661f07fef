//! Range checks of numeric settings fields. A check names the field, its value and the
//! allowed range in interval notation (`min_score = -1 is out of range [0, inf)`), so that a
//! settings file's error points at the one field to change.

use std::fmt::Display;

/// One end of the allowed interval of a real-valued field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bound {
    /// The value itself is allowed.
    Closed(f64),
    /// Only values strictly beyond it are allowed.
    Open(f64),
}

/// `Ok` when `lo <= v <= hi`, else `field = v is out of range lo..=hi` (counts and other
/// integers).
pub fn check_count<T: PartialOrd + Display + Copy>(field: &str, v: T, lo: T, hi: T) -> Result<(), String> {
    if v >= lo && v <= hi {
        Ok(())
    } else {
        Err(format!("{field} = {v} is out of range {lo}..={hi}"))
    }
}

/// `Ok` when `value` (`f32` or `f64`, shown as given) is finite and within `lo` and `hi`,
/// else `field = value is out of range [lo, hi)` (brackets after the bounds' kinds). NaN and
/// infinities are always out of range.
pub fn check_real<T: Into<f64> + Display + Copy>(field: &str, value: T, lo: Bound, hi: Bound) -> Result<(), String> {
    let v: f64 = value.into();
    let above = match lo {
        Bound::Closed(l) => v >= l,
        Bound::Open(l) => v > l,
    };
    let below = match hi {
        Bound::Closed(h) => v <= h,
        Bound::Open(h) => v < h,
    };
    if v.is_finite() && above && below {
        return Ok(());
    }
    let (open, lo) = match lo {
        Bound::Closed(l) => ('[', l),
        Bound::Open(l) => ('(', l),
    };
    let (close, hi) = match hi {
        Bound::Closed(h) => (']', h),
        Bound::Open(h) => (')', h),
    };
    Err(format!("{field} = {value} is out of range {open}{lo}, {hi}{close}"))
}

/// [`check_real`] of each `(field, value)` against one interval; the first field out of range
/// is the error.
pub fn check_all<T: Into<f64> + Display + Copy>(fields: &[(&str, T)], lo: Bound, hi: Bound) -> Result<(), String> {
    fields.iter().try_for_each(|&(name, v)| check_real(name, v, lo, hi))
}

#[cfg(test)]
mod tests {
    use super::Bound::{Closed, Open};
    use super::*;

    #[test]
    fn bounds_are_closed_or_open_and_non_finite_values_never_pass() {
        assert!(check_real("a", 0.0, Closed(0.0), Closed(1.0)).is_ok());
        assert_eq!(check_real("a", 0.0, Open(0.0), Closed(1.0)).unwrap_err(), "a = 0 is out of range (0, 1]");
        assert_eq!(check_real("b", 2.5, Closed(0.0), Open(f64::INFINITY)), Ok(()));
        assert_eq!(check_real("b", f64::INFINITY, Closed(0.0), Open(f64::INFINITY)).unwrap_err(), "b = inf is out of range [0, inf)");
        assert_eq!(check_real("c", f64::NAN, Closed(f64::NEG_INFINITY), Closed(f64::INFINITY)).unwrap_err(), "c = NaN is out of range [-inf, inf]");
        assert_eq!(check_real("f", 1.1f32, Closed(0.0), Closed(1.0)).unwrap_err(), "f = 1.1 is out of range [0, 1]");
        assert_eq!(check_count("n", 0usize, 1, 1000).unwrap_err(), "n = 0 is out of range 1..=1000");
        assert_eq!(check_all(&[("x", 0.5), ("y", -1.0), ("z", -2.0)], Closed(0.0), Closed(1.0)).unwrap_err(), "y = -1 is out of range [0, 1]");
    }
}
