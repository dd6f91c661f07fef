//! Confidence intervals by a cluster (group) bootstrap.
//!
//! Frames of one sol share terrain, light and camera pointing, so they are not independent
//! samples: an interval that resamples frames one by one is too narrow. Here the unit of
//! resampling is a *group* (e.g. the sol a frame was taken on). Each of `B` resamples draws `G`
//! groups uniformly with replacement from the `G` groups, the statistic is computed on the
//! union of their items (a group drawn twice counts twice), and the interval is the percentile
//! interval of the `B` values: the `(1 - level) / 2` and `(1 + level) / 2` quantiles, linearly
//! interpolated between order statistics (numpy's default).

use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// How a bootstrap interval is computed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BootstrapSpec {
    /// Number of resamples `B`.
    pub resamples: usize,
    /// Coverage of the interval, e.g. 0.95.
    pub level: f64,
    /// Seed of the resampling (ChaCha8); the same seed gives the same interval.
    pub seed: u64,
}

impl Default for BootstrapSpec {
    /// 2000 resamples, 95 %, seed 0.
    fn default() -> Self {
        BootstrapSpec { resamples: 2000, level: 0.95, seed: 0 }
    }
}

/// A statistic's value on all the data and its bootstrap interval.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Interval {
    /// The statistic on all the data (each group once).
    pub estimate: f64,
    /// Lower end of the interval.
    pub lo: f64,
    /// Upper end of the interval.
    pub hi: f64,
    /// Number of groups resampled.
    pub groups: usize,
}

impl BootstrapSpec {
    /// The groups drawn by each resample: `resamples` lists of `groups` indices in
    /// `0..groups`, uniformly with replacement. Empty when there is no group.
    pub fn draws(&self, groups: usize) -> Vec<Vec<usize>> {
        if groups == 0 {
            return Vec::new();
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(self.seed);
        (0..self.resamples).map(|_| (0..groups).map(|_| rng.random_range(0..groups)).collect()).collect()
    }

    /// The percentile interval of `values` (one per resample; NaNs, e.g. resamples where the
    /// statistic is undefined, are left out) around `estimate`. Without a value both ends are
    /// NaN.
    pub fn interval(&self, estimate: f64, mut values: Vec<f64>, groups: usize) -> Interval {
        values.retain(|v| !v.is_nan());
        values.sort_by(f64::total_cmp);
        let tail = (1.0 - self.level) / 2.0;
        Interval { estimate, lo: quantile(&values, tail), hi: quantile(&values, 1.0 - tail), groups }
    }

    /// The interval of a ratio of sums, `Σ num / Σ den` over the groups, from each group's
    /// `(num, den)`: e.g. false detections over frames, one entry per sol.
    pub fn ratio_of_sums(&self, per_group: &[(f64, f64)]) -> Interval {
        let ratio = |sel: &mut dyn Iterator<Item = &(f64, f64)>| {
            let (n, d) = sel.fold((0.0, 0.0), |(n, d), g| (n + g.0, d + g.1));
            if d > 0.0 {
                n / d
            } else {
                f64::NAN
            }
        };
        let estimate = ratio(&mut per_group.iter());
        let values = self.draws(per_group.len()).iter().map(|draw| ratio(&mut draw.iter().map(|&g| &per_group[g]))).collect();
        self.interval(estimate, values, per_group.len())
    }
}

impl BootstrapSpec {
    /// The interval of a statistic of pooled values, e.g. the median pose error: `groups[g]`
    /// holds group `g`'s values; each resample pools the values of the groups it drew (a group
    /// drawn twice counts twice) and applies `stat` to them, sorted ascending. The estimate is
    /// `stat` of all values; an empty pool gives NaN.
    pub fn pooled_statistic(&self, groups: &[Vec<f64>], stat: &(dyn Fn(&[f64]) -> f64 + Sync)) -> Interval {
        let pooled = |draw: &mut dyn Iterator<Item = usize>| {
            let mut v: Vec<f64> = draw.flat_map(|g| groups[g].iter().copied()).collect();
            if v.is_empty() {
                return f64::NAN;
            }
            v.sort_by(f64::total_cmp);
            stat(&v)
        };
        let estimate = pooled(&mut (0..groups.len()));
        let values = self.draws(groups.len()).iter().map(|d| pooled(&mut d.iter().copied())).collect();
        self.interval(estimate, values, groups.len())
    }
}

/// The median of sorted `v` (the mean of the two middle values for an even count; NaN for an
/// empty `v`).
pub fn median(v: &[f64]) -> f64 {
    quantile(v, 0.5)
}

/// The `q` quantile of sorted `v`, linearly interpolated (`numpy.quantile`'s default); NaN for
/// an empty `v`.
pub fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let (i, frac) = (pos.floor() as usize, pos - pos.floor());
    if i + 1 < v.len() {
        v[i] + frac * (v[i + 1] - v[i])
    } else {
        v[i]
    }
}

/// Groups items by a key: the item indices of each distinct key, in key order.
pub fn groups_by_key<K: Ord>(keys: impl IntoIterator<Item = K>) -> Vec<Vec<usize>> {
    let mut by: std::collections::BTreeMap<K, Vec<usize>> = std::collections::BTreeMap::new();
    for (i, k) in keys.into_iter().enumerate() {
        by.entry(k).or_default().push(i);
    }
    by.into_values().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_as_numpy_does() {
        let v = [1.0, 2.0, 3.0, 4.0];
        // numpy.quantile([1, 2, 3, 4], [0, 0.025, 0.5, 0.975, 1]) = 1, 1.075, 2.5, 3.925, 4
        for (q, want) in [(0.0, 1.0), (0.025, 1.075), (0.5, 2.5), (0.975, 3.925), (1.0, 4.0)] {
            assert!((quantile(&v, q) - want).abs() < 1e-12, "q {q}: {}", quantile(&v, q));
        }
        assert!(quantile(&[], 0.5).is_nan());
    }

    #[test]
    fn ratio_intervals_cover_the_estimate_and_follow_the_seed() {
        // Ten sols of two frames; one sol carries most of the false detections.
        let mut per_sol: Vec<(f64, f64)> = (0..9).map(|_| (1.0, 2.0)).collect();
        per_sol.push((21.0, 2.0));
        let spec = BootstrapSpec::default();
        let i = spec.ratio_of_sums(&per_sol);
        assert_eq!(i.estimate, 30.0 / 20.0);
        assert!(i.lo < i.estimate && i.estimate < i.hi, "{i:?}");
        // Without the heavy sol the ratio is 0.5; the interval reaches down toward it.
        assert!(i.lo < 0.8 && i.hi > 2.0, "{i:?}");
        assert_eq!(spec.ratio_of_sums(&per_sol), i, "same seed, same interval");
        assert_ne!(BootstrapSpec { seed: 1, ..spec }.draws(10), spec.draws(10), "another seed, other draws");
        // Equal groups: no spread.
        let flat = spec.ratio_of_sums(&[(1.0, 2.0); 5]);
        assert_eq!((flat.lo, flat.estimate, flat.hi), (0.5, 0.5, 0.5));
        // No group: NaN, not a panic.
        assert!(spec.ratio_of_sums(&[]).estimate.is_nan());
    }

    #[test]
    fn pooled_medians_take_each_group_whole() {
        // Three sols of small errors and one of large ones.
        let groups = vec![vec![0.5, 0.7, 0.6], vec![0.8, 0.4], vec![0.6, 0.9], vec![5.0, 6.0, 7.0]];
        let spec = BootstrapSpec::default();
        let i = spec.pooled_statistic(&groups, &median);
        assert_eq!(i.estimate, 0.75, "median of the ten values");
        assert!(i.lo <= 0.6 && i.hi >= 5.0, "the heavy sol moves the median when drawn twice: {i:?}");
        assert_eq!(spec.pooled_statistic(&groups, &median), i);
        assert_eq!(median(&[1.0, 2.0, 3.0]), 2.0);
        assert!(spec.pooled_statistic(&[], &median).estimate.is_nan());
    }

    #[test]
    fn draws_take_every_group_with_equal_chance() {
        let spec = BootstrapSpec { resamples: 4000, ..Default::default() };
        let draws = spec.draws(4);
        assert_eq!(draws.len(), 4000);
        let mut counts = [0usize; 4];
        for d in &draws {
            assert_eq!(d.len(), 4);
            for &g in d {
                counts[g] += 1;
            }
        }
        // 16000 draws, 4000 expected each (sd ~55).
        assert!(counts.iter().all(|&c| (3700..4300).contains(&c)), "{counts:?}");
        assert_eq!(groups_by_key(["b", "a", "b", "c"]), vec![vec![1], vec![0, 2], vec![3]]);
    }
}
