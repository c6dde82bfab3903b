//! Benefit and cost models (000 §5.3, dissertation §8.4 Eqs. 8.18–8.21, 001
//! §4.2): what a representation is worth on screen and what it costs to draw.
//!
//! Benefit has diminishing returns: the papers use square roots (`S·√(4^d /
//! 4^d_max)` for a terrain patch, `k S (N/64) √(x/N)` for a tree group), whose
//! slope is infinite at zero resolution. Here the root is *smoothed*,
//! `φ(u) = (√(u + s) − √s) / (√(1 + s) − √s)` on `u ∈ [0, 1]`: `φ(0) = 0`,
//! `φ(1) = 1`, concave, and `φ'(0) = 1 / (2 √s · norm)` is finite for
//! `s > 0` (with `s = 0` it is the papers' root, which the optimiser also
//! handles).
//!
//! Costs are linear in a few per-frame features ([`CostFeatures`]) with
//! constants that [`super::calibrate::CostCalibrator`] fits to measured frame
//! times.
//!
//! Invariant: every function returns a finite, non-negative number for any
//! finite input, and 0 for non-positive or non-finite sizes.

/// The smoothed square root `φ` with smoothing `s ≥ 0` (a fraction of full
/// resolution).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Smooth {
    /// Smoothing: the slope at 0 is that of `√u` at `u = s`.
    pub s: f64,
}

impl Default for Smooth {
    /// `s = 1/64`: one tree of a full group of 64 (or one splat in 64) is
    /// where the root's slope stops growing; `φ'(0) ≈ 4.5`.
    fn default() -> Smooth {
        Smooth { s: 1.0 / 64.0 }
    }
}

impl Smooth {
    /// `√(1 + s) − √s`, the normaliser that makes `φ(1) = 1`.
    pub fn norm(&self) -> f64 {
        let s = self.s.max(0.0);
        // (1+s) − s over the sum of the roots: no cancellation for tiny s.
        1.0 / ((1.0 + s).sqrt() + s.sqrt())
    }

    /// `φ(u)`, `u` clamped to [0, 1].
    pub fn phi(&self, u: f64) -> f64 {
        let s = self.s.max(0.0);
        let u = if u.is_nan() { 0.0 } else { u.clamp(0.0, 1.0) };
        // √(u+s) − √s = u / (√(u+s) + √s): exact near 0.
        let num = if u > 0.0 { u / ((u + s).sqrt() + s.sqrt()) } else { 0.0 };
        num / self.norm()
    }

    /// `φ'(u)`, infinite only at `u = 0` with `s = 0`.
    pub fn slope(&self, u: f64) -> f64 {
        let s = self.s.max(0.0);
        let u = if u.is_nan() { 0.0 } else { u.clamp(0.0, 1.0) };
        1.0 / (2.0 * (u + s).sqrt() * self.norm())
    }
}

/// Benefit of drawing a terrain tile of `samples_per_side²` samples that
/// covers `projected_px` pixels (dissertation Eq. 8.21 with the accuracy of
/// 001 §4.2): importance is the screen size, accuracy the smoothed root of
/// the fraction of those pixels that get a sample of their own, saturating
/// at 1 when the tile has as many samples as pixels. Four children of a
/// quarter of the size are worth at least the parent and at most four times
/// it (four times the cost): per tile drawn, a split never gains
/// (diminishing returns, 001 §3.1's condition for the greedy bound).
pub fn tile_benefit(projected_px: f64, samples_per_side: u32, smooth: Smooth) -> f64 {
    tile_benefit_seen(projected_px, projected_px, f64::from(samples_per_side).powi(2), smooth)
}

/// [`tile_benefit`] of a tile partly on screen: `visible_px` of it are
/// seen (the importance), and its `samples` are spread over `full_px`, the
/// pixels the whole tile would cover at the density of its nearest point
/// (the accuracy `φ(samples / full_px)`). A tile the camera hovers over
/// has a small `visible_px` of a huge `full_px`: worth refining. With
/// `full_px = visible_px` it is [`tile_benefit`]; four children, each with
/// a quarter of `full_px` and the parent's samples, keep its diminishing
/// returns (`φ` is concave with `φ(0) = 0`, so `φ(u) ≤ φ(4u) ≤ 4 φ(u)`).
pub fn tile_benefit_seen(visible_px: f64, full_px: f64, samples: f64, smooth: Smooth) -> f64 {
    let finite_positive = |x: f64| crate::lod::positive(x) && x.is_finite();
    if !finite_positive(visible_px) || !finite_positive(full_px.max(visible_px)) || !crate::lod::non_negative(samples) {
        return 0.0;
    }
    visible_px * smooth.phi(samples / full_px.max(visible_px))
}

/// Full-resolution benefit weight of a group of `trees` trees covering
/// `projected_px` pixels (dissertation Eq. 8.20 at `x = N`): importance `k S`
/// times the group's density `N / 64`. The optimiser multiplies it by
/// `φ(x / capacity)`.
pub fn group_weight(projected_px: f64, trees: u32, k: f64) -> f64 {
    if !crate::lod::positive(projected_px) || !projected_px.is_finite() || !crate::lod::positive(k) {
        return 0.0;
    }
    k * projected_px * f64::from(trees.min(64)) / 64.0
}

/// What one frame draws, as the cost model sees it. Each feature is in units
/// that keep its constant near 1 ms on a current GPU.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CostFeatures {
    /// Tiles drawn (draw calls, mesh vertices, texture binds).
    pub tiles: f64,
    /// View-ray casting work: millions of pixel·steps.
    pub raycast_mpx_steps: f64,
    /// Shadow-ray work: millions of pixel·shadow steps, each step weighed
    /// by the fetches it takes (fewer where rays stop early, more under a
    /// fading canopy).
    pub shadow_mpx_steps: f64,
    /// Point splats drawn, thousands.
    pub splats_k: f64,
    /// Tree groups drawn (per-group setup, 000 §5.3's `c_tree`), hundreds.
    pub groups_h: f64,
    /// Pixels the splats' quads cover, overlaps counted, millions: each
    /// covered pixel is a fragment shaded (splats write their depth), and
    /// a tree's splats cover its crown twice however many it has.
    pub splat_fill_mpx: f64,
    /// The part of the view-ray work cast through a fading canopy,
    /// millions of pixel·steps: what the fading pipeline costs beyond the
    /// whole canopy's (near the trees' blend and far away).
    pub faded_mpx_steps: f64,
}

/// Number of calibrated constants: one per feature plus a fixed per-frame
/// cost.
pub const FEATURES: usize = 8;

impl CostFeatures {
    /// The features as a vector, with 1 for the fixed per-frame cost first.
    pub fn vector(&self) -> [f64; FEATURES] {
        [
            1.0,
            self.tiles,
            self.raycast_mpx_steps,
            self.shadow_mpx_steps,
            self.splats_k,
            self.groups_h,
            self.splat_fill_mpx,
            self.faded_mpx_steps,
        ]
        .map(finite_non_negative)
    }

    /// Sum of two feature sets (a tile's and a group's, say).
    pub fn plus(&self, o: &CostFeatures) -> CostFeatures {
        CostFeatures {
            tiles: self.tiles + o.tiles,
            raycast_mpx_steps: self.raycast_mpx_steps + o.raycast_mpx_steps,
            shadow_mpx_steps: self.shadow_mpx_steps + o.shadow_mpx_steps,
            splats_k: self.splats_k + o.splats_k,
            groups_h: self.groups_h + o.groups_h,
            splat_fill_mpx: self.splat_fill_mpx + o.splat_fill_mpx,
            faded_mpx_steps: self.faded_mpx_steps + o.faded_mpx_steps,
        }
    }
}

/// Milliseconds per unit of each feature: `predicted = Σ cᵢ fᵢ` (000 §5.3:
/// `cost_d = c_vertex n`, `cost_c = c_splat N x + c_tree`). Serialised as
/// `{"units": 2, "constants_ms": [...]}`, so a model calibrated on one
/// machine can start the next flight there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CostModel {
    /// Fixed per-frame ms, then ms per unit of each [`CostFeatures`] field.
    pub constants_ms: [f64; FEATURES],
}

/// What the features measure, as saved with a model: 2 since shadow rays are
/// priced by their measured fetches (files without `units` are older, their
/// shadow constant per nominal shadow step).
const UNITS: u32 = 2;

/// A cost model's JSON form.
#[derive(serde::Serialize, serde::Deserialize)]
struct ModelFile {
    units: Option<u32>,
    constants_ms: [f64; FEATURES],
}

impl Default for CostModel {
    /// Starting guesses before any frame was measured: 0.5 ms per frame,
    /// 0.01 ms per tile, 1 ms per million pixel·steps of view or shadow
    /// rays, 0.006 ms per thousand splats, 0.01 ms per hundred groups, 20
    /// ms per million pixels of splat fill, 0.5 ms more per million
    /// pixel·steps through a fading canopy. The calibrator replaces them
    /// within a few frames, except where features move together (splats
    /// and their fill; rays and the fading canopy, which most of them
    /// cross): those keep the prior's proportions, so the splat, fill and
    /// fading constants are in the proportions measured on lavapipe
    /// (`docs/benchmarks.md`, "Trees priced by their fill").
    fn default() -> CostModel {
        CostModel { constants_ms: [0.5, 0.01, 1.0, 1.0, 0.006, 0.01, 20.0, 0.5] }
    }
}

impl CostModel {
    /// A model from its JSON form: in this version's units, every constant
    /// finite and not negative.
    pub fn from_json(text: &str) -> Result<CostModel, String> {
        let file: ModelFile = serde_json::from_str(text).map_err(|e| format!("not a cost model: {e}"))?;
        if file.units != Some(UNITS) {
            let units = file.units.map_or("none".into(), |u| u.to_string());
            return Err(format!(
                "a cost model in other units (units {units}, this sylva's are {UNITS}): \
                 fly once without --cost-model to calibrate a new one"
            ));
        }
        let model = CostModel { constants_ms: file.constants_ms };
        match model.constants_ms.iter().position(|c| !c.is_finite() || *c < 0.0) {
            Some(i) => Err(format!("constant {i} is {}, not a finite non-negative ms", model.constants_ms[i])),
            None => Ok(model),
        }
    }

    /// The model's JSON form, which [`CostModel::from_json`] reads.
    pub fn to_json(&self) -> String {
        let file = ModelFile { units: Some(UNITS), constants_ms: self.constants_ms };
        serde_json::to_string_pretty(&file).unwrap_or_default()
    }

    /// Predicted milliseconds for `features`.
    pub fn predict_ms(&self, features: &CostFeatures) -> f64 {
        features.vector().iter().zip(&self.constants_ms).map(|(f, c)| f * c).sum()
    }

    /// Milliseconds of the features alone, without the fixed per-frame cost
    /// (the cost of one representation).
    pub fn marginal_ms(&self, features: &CostFeatures) -> f64 {
        self.predict_ms(features) - self.constants_ms[0]
    }
}

fn finite_non_negative(x: f64) -> f64 {
    if x.is_finite() { x.max(0.0) } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn cost_models_round_trip_through_json_and_bad_ones_are_refused() {
        let model = CostModel { constants_ms: [2.5, 0.3, 40.0, 12.0, 0.0, 1e-3, 0.5, 20.0] };
        assert_eq!(CostModel::from_json(&model.to_json()), Ok(model));
        assert!(
            CostModel::from_json("{\"units\": 2, \"constants_ms\": [1, 2]}").unwrap_err().contains("not a cost model")
        );
        let negative = "{\"units\": 2, \"constants_ms\": [1, 2, 3, -4, 5, 6, 7, 8]}";
        assert!(CostModel::from_json(negative).unwrap_err().contains("constant 3 is -4"));
        assert!(CostModel::from_json("ms").is_err());
        let older = "{\"constants_ms\": [1, 2, 3, 4, 5, 6, 7, 8]}";
        assert!(CostModel::from_json(older).unwrap_err().contains("units none, this sylva's are 2"));
    }

    #[test]
    fn phi_is_normalised_with_finite_slope_at_zero() {
        let smooth = Smooth::default();
        assert_eq!(smooth.phi(0.0), 0.0);
        assert!((smooth.phi(1.0) - 1.0).abs() < 1e-15);
        assert!(smooth.slope(0.0).is_finite() && smooth.slope(0.0) > 4.0);
        let papers = Smooth { s: 0.0 };
        assert!((papers.phi(0.25) - 0.5).abs() < 1e-15, "s = 0 is the plain root");
        assert_eq!(papers.slope(0.0), f64::INFINITY);
        assert!(Smooth { s: 1e-300 }.phi(1e-300).is_finite());
    }

    proptest! {
        #[test]
        fn phi_is_increasing_and_concave(s in 0.0f64..1.0, a in 0.0f64..1.0, b in 0.0f64..1.0) {
            let f = Smooth { s };
            let (lo, hi) = (a.min(b), a.max(b));
            prop_assert!(f.phi(lo) <= f.phi(hi));
            let mid = 0.5 * (lo + hi);
            prop_assert!(f.phi(mid) >= 0.5 * (f.phi(lo) + f.phi(hi)) - 1e-12);
            prop_assert!(f.slope(lo) >= f.slope(hi));
        }

        #[test]
        fn splitting_a_tile_has_diminishing_returns(px in 1.0f64..1e7, n in 2u32..600) {
            // Four children of a quarter of the size: no loss, and per tile no gain.
            let f = Smooth::default();
            let parent = tile_benefit(px, n, f);
            let children = 4.0 * tile_benefit(px / 4.0, n, f);
            prop_assert!(children >= parent * (1.0 - 1e-12));
            prop_assert!(children <= 4.0 * parent * (1.0 + 1e-12));
        }

        #[test]
        fn a_partly_seen_tile_keeps_diminishing_returns(
            seen in 1.0f64..1e6, more in 1.0f64..1e4, n in 2u32..600, share in (0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0),
        ) {
            // The children share the seen pixels in any way; each spreads
            // the parent's samples over a quarter of its full size.
            let f = Smooth::default();
            let full = seen * more;
            let samples = f64::from(n).powi(2);
            let parent = tile_benefit_seen(seen, full, samples, f);
            let parts = [share.0, share.1 * (1.0 - share.0), share.2 * (1.0 - share.0) * (1.0 - share.1)];
            let rest = 1.0 - parts.iter().sum::<f64>();
            let children: f64 =
                parts.iter().chain([rest].iter()).map(|p| tile_benefit_seen(seen * p, full / 4.0, samples, f)).sum();
            prop_assert!(children >= parent * (1.0 - 1e-9));
            prop_assert!(children <= 4.0 * parent * (1.0 + 1e-9));
            prop_assert!(tile_benefit_seen(seen, seen, samples, f) == tile_benefit(seen, n, f));
        }
    }

    #[test]
    fn sizes_that_are_not_sizes_are_worth_nothing() {
        for px in [0.0, -3.0, f64::NAN, f64::INFINITY] {
            assert_eq!(tile_benefit(px, 64, Smooth::default()), 0.0);
            assert_eq!(group_weight(px, 64, 1.0), 0.0);
            assert_eq!(tile_benefit_seen(px, 1e6, 1e4, Smooth::default()), 0.0);
            assert_eq!(tile_benefit_seen(10.0, px, f64::NAN, Smooth::default()), 0.0);
        }
        let model = CostModel::default();
        let junk = CostFeatures {
            tiles: f64::NAN,
            raycast_mpx_steps: -1.0,
            shadow_mpx_steps: f64::NEG_INFINITY,
            splats_k: f64::INFINITY,
            groups_h: 2.0,
            splat_fill_mpx: 0.5,
            faded_mpx_steps: 0.0,
        };
        assert!((model.predict_ms(&junk) - (0.5 + 0.02 + 10.0)).abs() < 1e-12);
    }
}
