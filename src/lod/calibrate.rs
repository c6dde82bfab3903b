//! Cost feedback (001 §4.2): after each frame the measured frame time
//! corrects the cost model's constants "using a weighted average scheme".
//!
//! With one constant (001's `c_vertex`) that is a weighted moving average of
//! measured / predicted. Sylva's model has [`FEATURES`] constants (a fixed
//! per-frame cost, tiles, view- and shadow-ray work, splats, tree groups,
//! splat fill, view rays through a fading canopy),
//! so the average is taken over the normal equations instead: exponentially
//! weighted least squares, `A ← γA + f fᵀ`, `b ← γb + f·ms`, solved with a
//! small ridge toward the prior constants, whose per-item part is scaled by
//! a free factor (so the first frames make 001's single weighted average).
//! A frame's weight halves every `ln 2 / ln(1/γ)` frames (14 with the
//! default γ = 0.95), so the model follows a GPU that throttles within a
//! few dozen frames and forgets a scene it has left.
//!
//! Invariants: constants stay finite and non-negative; a non-finite or
//! non-positive measurement, or one far from the prediction after warm-up
//! (a hitch: shader compilation, a page fault), changes nothing, unless
//! more than [`MAX_HITCHES`] come in a row.

use super::model::{CostFeatures, CostModel, FEATURES};

/// Outliers in a row that are hitches; from the next one on they are
/// taken until a frame fits again: the model, not the frame, is off (else
/// a wrong model would never be corrected).
pub const MAX_HITCHES: u32 = 2;

/// Settings of a [`CostCalibrator`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CalibratorSettings {
    /// Weight kept by the past at each new frame (0 < γ < 1).
    pub forgetting: f64,
    /// Ridge toward the prior, relative to each feature's own diagonal
    /// entry of `A` (so it does not depend on the features' units): keeps
    /// constants whose features never vary (or vary together) at the prior.
    pub ridge: f64,
    /// Least ridge of a per-item constant, as a share of the ridge of the
    /// feature costing most under the prior (`Aⱼⱼ pⱼ²`, in ms²), so a
    /// feature seen rarely or small (a few tree groups now and then) keeps
    /// its constant near the prior's proportion instead of taking the
    /// whole error of the few frames it appears in (0: none).
    pub ridge_floor: f64,
    /// Frames before outliers are rejected.
    pub warmup_frames: u32,
    /// A measurement beyond this factor of the prediction (either way) is
    /// a hitch and is ignored after warm-up.
    pub outlier_ratio: f64,
}

impl Default for CalibratorSettings {
    fn default() -> CalibratorSettings {
        CalibratorSettings { forgetting: 0.95, ridge: 1e-3, ridge_floor: 0.0, warmup_frames: 10, outlier_ratio: 4.0 }
    }
}

/// Fits the cost model's constants to measured frame times.
#[derive(Clone, Debug)]
pub struct CostCalibrator {
    settings: CalibratorSettings,
    prior: CostModel,
    model: CostModel,
    a: [[f64; FEATURES]; FEATURES],
    b: [f64; FEATURES],
    frames: u32,
    /// Outliers rejected since the last frame that fitted.
    hitches: u32,
}

impl CostCalibrator {
    /// A calibrator starting from `prior`.
    pub fn new(prior: CostModel, settings: CalibratorSettings) -> CostCalibrator {
        CostCalibrator {
            settings,
            prior,
            model: prior,
            a: [[0.0; FEATURES]; FEATURES],
            b: [0.0; FEATURES],
            frames: 0,
            hitches: 0,
        }
    }

    /// The current model.
    pub fn model(&self) -> CostModel {
        self.model
    }

    /// Frames taken into account.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Records one frame: what was drawn and how long it took. Returns
    /// whether the frame was used.
    pub fn observe(&mut self, features: &CostFeatures, measured_ms: f64) -> bool {
        if !measured_ms.is_finite() || measured_ms <= 0.0 {
            return false;
        }
        let outlier = self.is_outlier(features, measured_ms);
        if outlier && self.hitches < MAX_HITCHES {
            self.hitches += 1;
            return false;
        }
        if !outlier {
            self.hitches = 0;
        }
        let f = features.vector();
        let g = self.settings.forgetting.clamp(0.0, 1.0);
        for i in 0..FEATURES {
            for j in 0..FEATURES {
                self.a[i][j] = g * self.a[i][j] + f[i] * f[j];
            }
            self.b[i] = g * self.b[i] + f[i] * measured_ms;
        }
        self.frames = self.frames.saturating_add(1);
        if let Some(c) = self.solve() {
            self.model = CostModel { constants_ms: c };
        }
        true
    }

    fn is_outlier(&self, features: &CostFeatures, measured_ms: f64) -> bool {
        if self.frames < self.settings.warmup_frames {
            return false;
        }
        let predicted = self.model.predict_ms(features);
        let r = self.settings.outlier_ratio.max(1.0);
        predicted > 0.0 && (measured_ms > predicted * r || measured_ms * r < predicted)
    }

    /// Ridge regression toward the prior with its per-item constants times
    /// a free factor `s` (001's single weighted average of the per-vertex
    /// constant): a few similar frames rescale the prior's per-item costs
    /// rather than load the whole error onto the constants whose features
    /// are small, and the fixed per-frame cost moves only as frames
    /// separate it. With `M = A + Λ`, the prior split into its fixed part
    /// `p₀` and per-item part `p̃`: `c(s) = M⁻¹(b + Λp₀) + s M⁻¹Λp̃`, `s`
    /// minimising the fit plus the ridge.
    ///
    /// Constants are non-negative (active set): the most negative one is
    /// fixed at 0 and the others fitted again, until none is negative.
    /// Clamping alone would keep the others' share of the negative one's
    /// (a biased prediction whenever its feature moves).
    fn solve(&self) -> Option<[f64; FEATURES]> {
        let mut free = [true; FEATURES];
        loop {
            let c = self.solve_free(&free)?;
            let worst = (0..FEATURES).filter(|&i| free[i] && c[i] < 0.0).min_by(|&i, &j| c[i].total_cmp(&c[j]));
            match worst {
                Some(i) => free[i] = false,
                None => return Some(c.map(|x| x.max(0.0))),
            }
        }
    }

    /// The ridge fit with the constants not `free` fixed at 0.
    fn solve_free(&self, free: &[bool; FEATURES]) -> Option<[f64; FEATURES]> {
        let a = self.restricted(free);
        let mut m = a;
        let lambda = self.ridges(&a, free);
        for i in 0..FEATURES {
            m[i][i] += lambda[i];
        }
        let keep = |i: usize, x: f64| if free[i] { x } else { 0.0 };
        let (fixed, scaled) = self.prior_parts();
        let c0 = gauss(m, std::array::from_fn(|i| keep(i, self.b[i] + lambda[i] * fixed[i])))?;
        let c1 = gauss(m, std::array::from_fn(|i| keep(i, lambda[i] * scaled[i])))?;
        let s = self.prior_scale(&a, (&c0, &c1), &lambda, free);
        let c: [f64; FEATURES] = std::array::from_fn(|i| c0[i] + s * c1[i]);
        c.iter().all(|x| x.is_finite()).then_some(c)
    }

    /// The ridge of each free constant: [`CalibratorSettings::ridge`] times
    /// its diagonal entry of `a`, or for a per-item constant at least its
    /// [`CalibratorSettings::ridge_floor`] share of the costliest feature's
    /// in ms² under the prior.
    fn ridges(&self, a: &[[f64; FEATURES]; FEATURES], free: &[bool; FEATURES]) -> [f64; FEATURES] {
        let p = &self.prior.constants_ms;
        let costliest = (1..FEATURES).filter(|&j| free[j]).map(|j| a[j][j] * p[j] * p[j]).fold(0.0, f64::max);
        let ridge = self.settings.ridge.max(0.0);
        std::array::from_fn(|i| {
            let floor =
                if i > 0 && p[i] > 0.0 { self.settings.ridge_floor.max(0.0) * costliest / (p[i] * p[i]) } else { 0.0 };
            if free[i] { ridge * a[i][i].max(floor) + 1e-12 } else { 0.0 }
        })
    }

    /// `A` with the rows and columns of fixed constants replaced by those
    /// of the identity (their constants solve to 0).
    fn restricted(&self, free: &[bool; FEATURES]) -> [[f64; FEATURES]; FEATURES] {
        std::array::from_fn(|i| {
            std::array::from_fn(|j| match (free[i], free[j]) {
                (true, true) => self.a[i][j],
                _ => f64::from(u8::from(i == j)),
            })
        })
    }

    /// The prior's fixed per-frame cost and its per-item constants, apart.
    fn prior_parts(&self) -> ([f64; FEATURES], [f64; FEATURES]) {
        let p = &self.prior.constants_ms;
        (
            std::array::from_fn(|i| if i == 0 { p[0] } else { 0.0 }),
            std::array::from_fn(|i| if i == 0 { 0.0 } else { p[i] }),
        )
    }

    /// The `s` minimising `cᵀAc − 2bᵀc + Σ λᵢ (cᵢ − p₀ᵢ − s p̃ᵢ)²` over
    /// `c = c0 + s c1` (its derivative set to zero), over the `free`
    /// constants of `a`; 1 if degenerate.
    fn prior_scale(
        &self,
        a: &[[f64; FEATURES]; FEATURES],
        (c0, c1): (&[f64; FEATURES], &[f64; FEATURES]),
        lambda: &[f64; FEATURES],
        free: &[bool; FEATURES],
    ) -> f64 {
        let (fixed, scaled) = self.prior_parts();
        let a_form = |x: &[f64; FEATURES], y: &[f64; FEATURES]| -> f64 {
            (0..FEATURES).map(|i| (0..FEATURES).map(|j| x[i] * a[i][j] * y[j]).sum::<f64>()).sum()
        };
        let b_c1: f64 = (0..FEATURES).filter(|&i| free[i]).map(|i| self.b[i] * c1[i]).sum();
        let ridge_num: f64 = (0..FEATURES).map(|i| lambda[i] * (c0[i] - fixed[i]) * (c1[i] - scaled[i])).sum();
        let ridge_den: f64 = (0..FEATURES).map(|i| lambda[i] * (c1[i] - scaled[i]).powi(2)).sum();
        let (num, den) = (a_form(c1, c0) - b_c1 + ridge_num, a_form(c1, c1) + ridge_den);
        let s = -num / den;
        if s.is_finite() && den > 0.0 { s.max(0.0) } else { 1.0 }
    }
}

/// Solves a small dense system by Gaussian elimination with partial
/// pivoting; `None` if it is singular.
pub(crate) fn gauss<const N: usize>(mut m: [[f64; N]; N], mut rhs: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let pivot = (col..N).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        if m[pivot][col].abs().partial_cmp(&1e-300) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        m.swap(col, pivot);
        rhs.swap(col, pivot);
        for row in col + 1..N {
            let k = m[row][col] / m[col][col];
            let pivot_row = m[col];
            for (x, p) in m[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= k * p;
            }
            rhs[row] -= k * rhs[col];
        }
    }
    let mut x = [0.0; N];
    for row in (0..N).rev() {
        let tail: f64 = (row + 1..N).map(|j| m[row][j] * x[j]).sum();
        x[row] = (rhs[row] - tail) / m[row][row];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::{hash2, unit};

    const TRUTH: CostModel = CostModel { constants_ms: [3.0, 0.004, 2.5, 0.8, 0.03, 0.05, 0.4, 0.6] };

    /// A frame's features, varying like a flyover: `k` seeds the hash.
    fn frame(k: i64) -> CostFeatures {
        let h = hash2(k, 7, 99);
        CostFeatures {
            tiles: 200.0 + 800.0 * unit(h, 0),
            raycast_mpx_steps: 1.0 + 6.0 * unit(h, 1),
            shadow_mpx_steps: 0.5 + 4.0 * unit(hash2(k, 11, 99), 0),
            splats_k: 100.0 + 900.0 * unit(h, 2),
            groups_h: 5.0 + 40.0 * unit(h, 3),
            splat_fill_mpx: 0.2 + 3.0 * unit(hash2(k, 13, 99), 0),
            faded_mpx_steps: 0.2 + 2.0 * unit(hash2(k, 17, 99), 0),
        }
    }

    /// Measured time with ±3 % noise.
    fn measure(model: &CostModel, f: &CostFeatures, k: i64) -> f64 {
        model.predict_ms(f) * (1.0 + 0.06 * (unit(hash2(k, 3, 5), 0) - 0.5))
    }

    fn relative_error(calibrated: &CostModel, truth: &CostModel, from: i64) -> f64 {
        (from..from + 100)
            .map(|k| {
                let f = frame(k);
                (calibrated.predict_ms(&f) / truth.predict_ms(&f) - 1.0).abs()
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn converges_to_the_true_constants() {
        // A GPU that does not change: a long memory (a half-life of 69
        // frames) separates eight constants under 3 % noise.
        let settings = CalibratorSettings { forgetting: 0.99, ..CalibratorSettings::default() };
        let mut cal = CostCalibrator::new(CostModel::default(), settings);
        assert!(relative_error(&cal.model(), &TRUTH, 10_000) > 0.3, "the prior is far off");
        for k in 0..600 {
            assert!(cal.observe(&frame(k), measure(&TRUTH, &frame(k), k)));
        }
        assert!(relative_error(&cal.model(), &TRUTH, 10_000) < 0.05);
        for (c, t) in cal.model().constants_ms.iter().zip(TRUTH.constants_ms) {
            assert!((c / t - 1.0).abs() < 0.25, "{c} vs {t}");
        }
    }

    #[test]
    fn a_few_similar_frames_rescale_the_prior() {
        // One scene seen over and over: nothing separates the constants,
        // so the per-item ones keep the prior's proportions, the fixed cost
        // stays, and the model predicts what was measured.
        let prior = CostModel::default();
        let mut cal = CostCalibrator::new(prior, CalibratorSettings::default());
        let measured = 2.0 * prior.predict_ms(&frame(0));
        for k in 0..3 {
            assert!(cal.observe(&frame(0), measured + f64::from(k)));
        }
        let c = cal.model().constants_ms;
        assert!((c[0] - prior.constants_ms[0]).abs() < 1e-6, "{c:?}");
        let ratio: Vec<f64> = c.iter().zip(prior.constants_ms).skip(1).map(|(c, p)| c / p).collect();
        assert!(ratio[0] > 1.0 && ratio.iter().all(|r| (r / ratio[0] - 1.0).abs() < 1e-6), "{ratio:?}");
        assert!((cal.model().predict_ms(&frame(0)) - (measured + 1.0)).abs() < 0.5, "{:?}", cal.model());
    }

    #[test]
    fn a_feature_seen_rarely_keeps_its_constant_near_the_prior_proportion() {
        // Frames without tree groups, and now and then a frame with a few
        // that runs 5 ms slow (noise): without the floor the group constant
        // takes that error whole.
        let calibrated = |ridge_floor: f64| {
            let settings = CalibratorSettings { ridge: 1e-3, ridge_floor, ..CalibratorSettings::default() };
            let mut cal = CostCalibrator::new(CostModel::default(), settings);
            for k in 0..60 {
                let groups_h = if k % 20 == 19 { 0.03 } else { 0.0 };
                let f = CostFeatures { splats_k: 0.0, groups_h, ..frame(k) };
                let slow = if groups_h > 0.0 { 5.0 } else { 0.0 };
                cal.observe(&f, TRUTH.predict_ms(&f) + slow);
            }
            let c = cal.model().constants_ms;
            // The group constant over the raycast one, against the prior's.
            let prior = CostModel::default().constants_ms;
            (c[5] / c[2]) / (prior[5] / prior[2])
        };
        let (without, with) = (calibrated(0.0), calibrated(0.3));
        assert!(without > 100.0, "{without}");
        assert!(with < 10.0, "{with}");
    }

    #[test]
    fn follows_a_throttling_gpu() {
        let mut cal = CostCalibrator::new(CostModel::default(), CalibratorSettings::default());
        for k in 0..300 {
            cal.observe(&frame(k), measure(&TRUTH, &frame(k), k));
        }
        let slow = CostModel { constants_ms: TRUTH.constants_ms.map(|c| 1.5 * c) };
        for k in 300..380 {
            cal.observe(&frame(k), measure(&slow, &frame(k), k));
        }
        assert!(relative_error(&cal.model(), &slow, 10_000) < 0.05);
    }

    #[test]
    fn junk_and_hitches_change_nothing() {
        let mut cal = CostCalibrator::new(CostModel::default(), CalibratorSettings::default());
        for k in 0..50 {
            cal.observe(&frame(k), measure(&TRUTH, &frame(k), k));
        }
        let before = cal.model();
        for ms in [f64::NAN, f64::INFINITY, -1.0, 0.0, 1e6, 1e-6] {
            assert!(!cal.observe(&frame(1), ms), "{ms}");
        }
        assert_eq!(cal.model(), before);
        assert_eq!(cal.frames(), 50);
    }

    #[test]
    fn a_lasting_change_is_not_a_hitch() {
        let mut cal = CostCalibrator::new(CostModel::default(), CalibratorSettings::default());
        for k in 0..100 {
            cal.observe(&frame(k), measure(&TRUTH, &frame(k), k));
        }
        // Five times slower for good: two frames are taken for hitches,
        // then every frame until the model fits again.
        let slow = CostModel { constants_ms: TRUTH.constants_ms.map(|c| 5.0 * c) };
        let used: Vec<bool> = (100..400).map(|k| cal.observe(&frame(k), measure(&slow, &frame(k), k))).collect();
        assert_eq!(used[..4], [false, false, true, true]);
        let error = relative_error(&cal.model(), &slow, 10_000);
        assert!(error < 0.05, "{error} after {} frames used", used.iter().filter(|u| **u).count());
    }

    #[test]
    fn a_constant_fixed_at_zero_leaves_the_others_refitted() {
        // Frames that a negative splat constant would fit best: with it
        // held at 0 the others absorb what they can, so the fit stays
        // unbiased (clamping alone over-predicts by the dropped share).
        let mut cal = CostCalibrator::new(CostModel::default(), CalibratorSettings::default());
        let fitted = |k: i64| 20.0 + 4.0 * frame(k).raycast_mpx_steps - 0.01 * frame(k).splats_k;
        for k in 0..200 {
            cal.observe(&frame(k), fitted(k));
        }
        let c = cal.model().constants_ms;
        assert_eq!(c[4], 0.0, "{c:?}");
        assert!(c.iter().all(|x| x.is_finite() && *x >= 0.0), "{c:?}");
        let bias = (150..200).map(|k| cal.model().predict_ms(&frame(k)) - fitted(k)).sum::<f64>() / 50.0;
        assert!(bias.abs() < 0.5, "mean error {bias} ms over frames of ~{} ms", fitted(150));
    }

    #[test]
    fn collinear_features_still_predict() {
        // Splats always 20 × groups: the split between the two constants is
        // not identifiable, but predictions are, and nothing blows up.
        let mut cal = CostCalibrator::new(CostModel::default(), CalibratorSettings::default());
        let tied = |k: i64| CostFeatures { splats_k: 20.0 * frame(k).groups_h, ..frame(k) };
        for k in 0..300 {
            cal.observe(&tied(k), measure(&TRUTH, &tied(k), k));
        }
        let worst = (10_000..10_100)
            .map(|k| (cal.model().predict_ms(&tied(k)) / TRUTH.predict_ms(&tied(k)) - 1.0).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.05, "{worst}");
        assert!(cal.model().constants_ms.iter().all(|c| c.is_finite() && *c >= 0.0));
    }
}
