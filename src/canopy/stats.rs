//! Height statistics of canopy height models and proxies (for `sylva info`,
//! `sylva canopy` and the tileability checks): mean, quantiles, maximum.
//!
//! Invariant: nodata (NaN) is skipped; quantiles are nearest-rank, so they
//! are heights that occur.

use std::fmt;

/// Summary of a set of heights.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HeightStats {
    /// Number of heights.
    pub count: usize,
    /// Mean, metres.
    pub mean: f32,
    /// 10th, 50th and 90th percentiles, metres.
    pub p10: f32,
    /// Median.
    pub p50: f32,
    /// 90th percentile.
    pub p90: f32,
    /// Largest, metres.
    pub max: f32,
}

impl HeightStats {
    /// Statistics of the valid values.
    pub fn of(values: impl Iterator<Item = f32>) -> HeightStats {
        let v = sorted(values);
        if v.is_empty() {
            return HeightStats::default();
        }
        let mean = (v.iter().map(|&h| f64::from(h)).sum::<f64>() / v.len() as f64) as f32;
        let q = |p: f64| sorted_quantile(&v, p);
        HeightStats { count: v.len(), mean, p10: q(0.1), p50: q(0.5), p90: q(0.9), max: v[v.len() - 1] }
    }
}

impl fmt::Display for HeightStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "mean {:.1} m, p10 {:.1}, p50 {:.1}, p90 {:.1}, max {:.1} m",
            self.mean, self.p10, self.p50, self.p90, self.max
        )
    }
}

/// The `q` quantile (nearest rank) of sorted values.
pub fn sorted_quantile(sorted: &[f32], q: f64) -> f32 {
    match sorted.len() {
        0 => f32::NAN,
        n => sorted[((q.clamp(0.0, 1.0) * (n - 1) as f64).round() as usize).min(n - 1)],
    }
}

/// The valid values, sorted.
pub fn sorted(values: impl Iterator<Item = f32>) -> Vec<f32> {
    let mut v: Vec<f32> = values.filter(|v| !v.is_nan()).collect();
    v.sort_unstable_by(f32::total_cmp);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_skip_nodata_and_rank_the_rest() {
        let s = HeightStats::of([f32::NAN, 4.0, 0.0, 2.0, 10.0, 1.0].into_iter());
        assert_eq!((s.count, s.mean, s.p50, s.max), (5, 3.4, 2.0, 10.0));
        assert_eq!(HeightStats::of(std::iter::empty()).count, 0);
    }
}
