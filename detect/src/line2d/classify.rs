//! Verification of Line2D detections against real clutter: a few radiometric and geometric
//! features of each detection and a logistic classifier fitted on detections in composites of
//! rendered tubes on real training frames.
//!
//! Line2D matches gradient orientations along a silhouette's contour only. On real rover
//! frames straight rock edges, bedrock layers, shadow borders and slab seams give contours as
//! good as a tube's. What tells a tube apart is what lies inside and beside the contour: a
//! tube is a smooth bright cylinder, brighter than the ground on *both* of its long sides,
//! with little texture on its surface. For a detection (template `t` placed at `(x, y)` in the
//! luminance image `L` at the library's pixel scale) the features are, over the template's
//! fixed sample sets ([`crate::line2d::verify::TemplateSamples`]: inside samples, ring
//! samples split into the two long sides and the ends, contour feature points):
//!
//! | # | name | value |
//! |---|---|---|
//! | 0 | `similarity` | Line2D similarity / 100 |
//! | 1 | `contrast` | `(mean_in L - mean_ring L) / (mean_ring L + 1)`, clamped to [-1, 3] |
//! | 2 | `side_min` | the smaller of that contrast against each long side's ring samples |
//! | 3 | `side_diff` | the absolute difference of the two side contrasts |
//! | 4 | `inside_cv` | standard deviation / (mean + 1) of `L` over the inside samples |
//! | 5 | `ring_cv` | the same over the ring samples |
//! | 6 | `inside_grad` | mean central-difference gradient `|dL/dx| + |dL/dy|` at inside samples / (mean_in + 1) |
//! | 7 | `edge_grad` | the same at the contour feature points / (mean_ring + 1) |
//! | 8 | `visible` | fraction of the inside samples that fall inside the image |
//! | 9 | `log_area` | natural log of the silhouette area, pixels at the library's scale |
//! | 10 | `brightness` | mean_in L / 255 |
//!
//! Each costs O(samples) per detection, with no allocation. The classifier is logistic on the
//! features and their pairwise products (quadratic terms `t`: the 11 features, then
//! `f_i f_j` for `i <= j`, 77 terms), `P = 1 / (1 + exp(-(b + Σ w_k (t_k - μ_k) / σ_k)))`: a
//! tube is e.g. "bright against both sides *and* similar", which a linear model cannot say.
//! The weights shipped in
//! `verifier.json` were fitted by `tubeloc templates fit-verifier` (the command is recorded in
//! the file), and its `threshold` is the default cut on `P`.

use crate::line2d::template::Template;
use crate::line2d::verify::TemplateSamples;
use serde::{Deserialize, Serialize};

/// Number of verification features.
pub const N_FEATURES: usize = 11;

/// Names of the features, in order (see the module doc).
pub const FEATURE_NAMES: [&str; N_FEATURES] = ["similarity", "contrast", "side_min", "side_diff", "inside_cv", "ring_cv", "inside_grad", "edge_grad", "visible", "log_area", "brightness"];

/// The feature vector of one detection.
pub type Features = [f32; N_FEATURES];

/// Number of classifier terms: the features and their pairwise products `f_i f_j`, `i <= j`.
pub const N_TERMS: usize = N_FEATURES + N_FEATURES * (N_FEATURES + 1) / 2;

/// The classifier terms of a feature vector (see the module doc).
pub fn terms(f: &Features) -> [f32; N_TERMS] {
    let mut t = [0f32; N_TERMS];
    t[..N_FEATURES].copy_from_slice(f);
    let mut k = N_FEATURES;
    for i in 0..N_FEATURES {
        for j in i..N_FEATURES {
            t[k] = f[i] * f[j];
            k += 1;
        }
    }
    t
}

/// A fitted logistic verifier: standardization, weights, bias and the default cut.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Verifier {
    /// Feature names, in order (checked against [`FEATURE_NAMES`] when loaded).
    pub features: Vec<String>,
    /// Mean of each classifier term ([`terms`]) over the training samples (standardization).
    pub mean: Vec<f32>,
    /// Standard deviation of each term over the training samples (at least 1e-6).
    pub std: Vec<f32>,
    /// Weight of each standardized term.
    pub weights: Vec<f32>,
    /// Bias (log-odds at the mean feature vector).
    pub bias: f32,
    /// Default cut on the probability: detections below it are dropped.
    pub threshold: f32,
    /// Cut on the probability for grey images (all three channels equal, e.g. Navcam), when
    /// it differs from `threshold` (which then applies to colour images). Chosen on tube-free
    /// grey validation frames: grey clutter (bright clasts on darker ground) passes the
    /// verifier more often than colour clutter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threshold_grey: Option<f32>,
    /// Cut on the probability for every detection of an image searched twice (the far search
    /// ran on it too, [`crate::line2d::MatchParams::far_scale_grey`]), of either kind, when it
    /// differs from the image kind's cut: the second search adds its own clutter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threshold_far: Option<f32>,
    /// How the weights and the threshold were obtained (command, data, figures).
    #[serde(default)]
    pub provenance: serde_json::Value,
}

/// The verifier shipped with the library (fitted weights; see `verifier.json`).
const SHIPPED: &str = include_str!("verifier.json");

impl Verifier {
    /// The shipped verifier (weights fitted on training composites, threshold chosen on the
    /// validation composites).
    pub fn shipped() -> Verifier {
        // The file is part of the source tree and checked by a unit test.
        Verifier::from_json(SHIPPED).unwrap_or_else(|e| panic!("the embedded verifier.json is invalid: {e}"))
    }

    /// Parses and checks a verifier JSON.
    pub fn from_json(text: &str) -> Result<Verifier, String> {
        let v: Verifier = serde_json::from_str(text).map_err(|e| e.to_string())?;
        v.check()?;
        Ok(v)
    }

    /// Checks the lengths, the names, and numbers that keep every term of the log-odds finite:
    /// mean, weights and bias within ±1e6, standard deviations of at least 1e-6 (what a fit
    /// gives; beyond them a term overflows to ±∞ and two such terms sum to NaN).
    pub fn check(&self) -> Result<(), String> {
        if self.features.len() != N_FEATURES || self.features.iter().zip(FEATURE_NAMES).any(|(a, b)| a != b) {
            return Err(format!("features {:?} differ from {:?}", self.features, FEATURE_NAMES));
        }
        if self.mean.len() != N_TERMS || self.std.len() != N_TERMS || self.weights.len() != N_TERMS {
            return Err(format!("mean, std and weights need {N_TERMS} values each"));
        }
        let all = self.mean.iter().chain(&self.std).chain(&self.weights).chain([&self.bias, &self.threshold]);
        if all.clone().any(|x| !x.is_finite()) {
            return Err("non-finite value".into());
        }
        if self.mean.iter().chain(&self.weights).chain([&self.bias]).any(|x| x.abs() > 1e6) {
            return Err("mean, weights and bias must be within ±1e6".into());
        }
        if let Some(s) = self.std.iter().find(|&&s| s < 1e-6) {
            return Err(format!("std {s} is below 1e-6"));
        }
        for (name, t) in [("threshold", Some(self.threshold)), ("threshold_grey", self.threshold_grey), ("threshold_far", self.threshold_far)] {
            if let Some(t) = t.filter(|t| !(0.0..=1.0).contains(t)) {
                return Err(format!("{name} {t} is not a probability"));
            }
        }
        Ok(())
    }

    /// The cut on the probability for an image that is grey (`grey`) or colour.
    pub fn threshold_for(&self, grey: bool) -> f32 {
        if grey {
            self.threshold_grey.unwrap_or(self.threshold)
        } else {
            self.threshold
        }
    }

    /// The cut on the probability for a detection of a grey or colour image searched once
    /// (`two_searches` false) or also by the far search (`two_searches` true).
    pub fn threshold_for_search(&self, grey: bool, two_searches: bool) -> f32 {
        match self.threshold_far {
            Some(t) if two_searches => t,
            _ => self.threshold_for(grey),
        }
    }

    /// Sets one cut for every image and search (`tubeloc detect --min-probability`).
    pub fn set_threshold(&mut self, t: f32) {
        self.threshold = t;
        self.threshold_grey = None;
        self.threshold_far = None;
    }

    /// Log-odds of a feature vector.
    pub fn logit(&self, f: &Features) -> f32 {
        let t = terms(f);
        self.bias + (0..N_TERMS).map(|i| self.weights[i] * (t[i] - self.mean[i]) / self.std[i]).sum::<f32>()
    }

    /// Probability that a detection with features `f` is a tube (under the training prior).
    pub fn probability(&self, f: &Features) -> f32 {
        1.0 / (1.0 + (-self.logit(f)).exp())
    }

    /// Fits a ridge-regularized logistic regression to `(features, is_tube)` samples by
    /// Newton's method (iteratively reweighted least squares) on standardized features;
    /// deterministic. `l2` is the ridge weight on the standardized weights (not on the bias);
    /// positives and negatives are weighted so that each class has the same total weight.
    /// The threshold is left at 0.5.
    pub fn fit(samples: &[(Features, bool)], l2: f64) -> Result<Verifier, String> {
        let n_pos = samples.iter().filter(|s| s.1).count();
        let n_neg = samples.len() - n_pos;
        if n_pos < 2 || n_neg < 2 {
            return Err(format!("need at least 2 positives and 2 negatives, got {n_pos} and {n_neg}"));
        }
        let n = samples.len() as f64;
        let rows: Vec<[f32; N_TERMS]> = samples.iter().map(|(f, _)| terms(f)).collect();
        let mut mean = [0f64; N_TERMS];
        let mut var = [0f64; N_TERMS];
        for t in &rows {
            for i in 0..N_TERMS {
                mean[i] += t[i] as f64 / n;
            }
        }
        for t in &rows {
            for i in 0..N_TERMS {
                var[i] += (t[i] as f64 - mean[i]).powi(2) / n;
            }
        }
        let std: Vec<f64> = var.iter().map(|v| v.sqrt().max(1e-6)).collect();
        let (wp, wn) = (n / (2.0 * n_pos as f64), n / (2.0 * n_neg as f64));
        const D: usize = N_TERMS + 1;
        let x_of = |t: &[f32; N_TERMS]| -> nalgebra::DVector<f64> {
            let mut x = nalgebra::DVector::from_element(D, 1.0);
            for i in 0..N_TERMS {
                x[i + 1] = (t[i] as f64 - mean[i]) / std[i];
            }
            x
        };
        let xs: Vec<nalgebra::DVector<f64>> = rows.iter().map(x_of).collect();
        let mut beta = nalgebra::DVector::<f64>::zeros(D);
        for _ in 0..50 {
            let mut h = nalgebra::DMatrix::<f64>::zeros(D, D);
            let mut g = nalgebra::DVector::<f64>::zeros(D);
            for (x, (_, y)) in xs.iter().zip(samples) {
                let p = 1.0 / (1.0 + (-beta.dot(x)).exp());
                let w = if *y { wp } else { wn };
                g.axpy(w * (p - *y as u8 as f64), x, 1.0);
                h.ger(w * (p * (1.0 - p)).max(1e-9), x, x, 1.0);
            }
            for i in 1..D {
                g[i] += l2 * beta[i];
                h[(i, i)] += l2;
            }
            let Some(step) = h.cholesky().map(|c| c.solve(&g)) else {
                return Err("singular Hessian".into());
            };
            beta -= &step;
            if step.norm() < 1e-9 {
                break;
            }
        }
        let v = Verifier {
            features: FEATURE_NAMES.iter().map(|s| s.to_string()).collect(),
            mean: mean.iter().map(|&m| m as f32).collect(),
            std: std.iter().map(|&s| s as f32).collect(),
            weights: (1..D).map(|i| beta[i] as f32).collect(),
            bias: beta[0] as f32,
            threshold: 0.5,
            threshold_grey: None,
            threshold_far: None,
            provenance: serde_json::Value::Null,
        };
        v.check()?;
        Ok(v)
    }
}

/// Central-difference gradient `|dL/dx| + |dL/dy|` at `(x, y)` (0 on the image border).
#[inline]
fn grad(luma: &[u8], w: usize, h: usize, x: usize, y: usize) -> f32 {
    if x == 0 || y == 0 || x + 1 >= w || y + 1 >= h {
        return 0.0;
    }
    let at = |xx: usize, yy: usize| luma[yy * w + xx] as i32;
    ((at(x + 1, y) - at(x - 1, y)).abs() + (at(x, y + 1) - at(x, y - 1)).abs()) as f32
}

/// Running sums of `L` and `L²` over the samples that fall inside the image.
#[derive(Default, Clone, Copy)]
struct Acc {
    n: u32,
    s: f64,
    s2: f64,
}

impl Acc {
    fn add(&mut self, v: f32) {
        self.n += 1;
        self.s += v as f64;
        self.s2 += (v as f64) * (v as f64);
    }
    fn mean(&self) -> Option<f64> {
        (self.n > 0).then(|| self.s / self.n as f64)
    }
    fn cv(&self) -> f64 {
        match self.mean() {
            Some(m) => (self.s2 / self.n as f64 - m * m).max(0.0).sqrt() / (m + 1.0),
            None => 0.0,
        }
    }
}

/// The verification features of template `t` (with its samples `s`) placed with its top-left
/// pixel at `(x, y)` in the `w x h` luminance image `luma`, given its Line2D similarity in
/// percent. `None` when fewer than a quarter of the inside or ring samples fall inside the
/// image.
#[allow(clippy::too_many_arguments)]
pub fn features(luma: &[u8], w: usize, h: usize, t: &Template, s: &TemplateSamples, x: i32, y: i32, similarity: f32) -> Option<Features> {
    let place = |dx: i16, dy: i16| -> Option<(usize, usize)> {
        let (xx, yy) = (x + dx as i32, y + dy as i32);
        (xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h).then_some((xx as usize, yy as usize))
    };
    let (mut inside, mut in_grad) = (Acc::default(), 0f64);
    for &(dx, dy) in &s.inside {
        if let Some((xx, yy)) = place(dx, dy) {
            inside.add(luma[yy * w + xx] as f32);
            in_grad += grad(luma, w, h, xx, yy) as f64;
        }
    }
    let mut ring = Acc::default();
    let mut sides = [Acc::default(); 3];
    for (k, &(dx, dy)) in s.ring.iter().enumerate() {
        if let Some((xx, yy)) = place(dx, dy) {
            let v = luma[yy * w + xx] as f32;
            ring.add(v);
            sides[s.side.get(k).copied().unwrap_or(2).min(2) as usize].add(v);
        }
    }
    if (inside.n as usize) * 4 < s.inside.len() || (ring.n as usize) * 4 < s.ring.len() || inside.n == 0 || ring.n == 0 {
        return None;
    }
    let (mi, mr) = (inside.mean()?, ring.mean()?);
    let c = |r: f64| ((mi - r) / (r + 1.0)).clamp(-1.0, 3.0);
    let contrast = c(mr);
    let (ca, cb) = (sides[0].mean().map_or(contrast, c), sides[1].mean().map_or(contrast, c));
    let (mut edge, mut n_edge) = (0f64, 0u32);
    for f in &t.levels[0].features {
        if let Some((xx, yy)) = place(f.x as i16, f.y as i16) {
            edge += grad(luma, w, h, xx, yy) as f64;
            n_edge += 1;
        }
    }
    Some([
        similarity / 100.0,
        contrast as f32,
        ca.min(cb) as f32,
        (ca - cb).abs() as f32,
        inside.cv() as f32,
        ring.cv() as f32,
        (in_grad / inside.n as f64 / (mi + 1.0)) as f32,
        (edge / n_edge.max(1) as f64 / (mr + 1.0)) as f32,
        inside.n as f32 / s.inside.len().max(1) as f32,
        (t.area.max(1) as f32).ln(),
        (mi / 255.0) as f32,
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_verifier_parses_and_has_the_feature_names() {
        let v = Verifier::shipped();
        assert_eq!(v.features, FEATURE_NAMES.iter().map(|s| s.to_string()).collect::<Vec<_>>());
        assert!((0.0..=1.0).contains(&v.threshold));
    }

    /// A verifier file whose terms would overflow (a tiny std, huge weights of opposite signs:
    /// ∞ - ∞ = NaN log-odds) is refused; the shipped one is within the bounds.
    #[test]
    fn a_verifier_whose_terms_overflow_is_refused() {
        let shipped = Verifier::shipped();
        assert!(shipped.check().is_ok());
        let tiny_std = Verifier { std: vec![1e-30; N_TERMS], ..shipped.clone() };
        assert!(tiny_std.check().unwrap_err().contains("below 1e-6"));
        let mut huge = shipped.clone();
        huge.weights[0] = 3e38;
        huge.weights[1] = -3e38;
        assert!(huge.check().unwrap_err().contains("within"));
        let text = serde_json::to_string(&tiny_std).unwrap();
        assert!(Verifier::from_json(&text).is_err());
    }

    #[test]
    fn fit_separates_a_separable_feature_and_is_deterministic() {
        // Positives have a high contrast, negatives a low one; the rest is seeded noise.
        let mut state = 99u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 33) as f64 / (1u64 << 31) as f64) as f32
        };
        let samples: Vec<(Features, bool)> = (0..400)
            .map(|i| {
                let y = i % 3 == 0;
                let mut f = [0f32; N_FEATURES];
                for v in f.iter_mut() {
                    *v = next();
                }
                f[1] = if y { 0.6 + 0.3 * next() } else { 0.4 * next() - 0.1 };
                (f, y)
            })
            .collect();
        let v = Verifier::fit(&samples, 1e-2).unwrap();
        let correct = samples.iter().filter(|(f, y)| (v.probability(f) > 0.5) == *y).count();
        assert!(correct >= 396, "{correct} of 400");
        assert!(v.weights[1] > 0.0);
        assert_eq!(v, Verifier::fit(&samples, 1e-2).unwrap());
    }
}
