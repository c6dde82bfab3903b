//! Blending canopy heights without washing them out.
//!
//! A plain weighted mean of two unrelated canopies halves their contrast
//! where both weigh ½: crowns become low mounds and gaps shallow pits. The
//! variance-preserving blend of Heitz and Neyret ("High-performance
//! by-example noise using a histogram-preserving blending operator", 2018)
//! keeps the contrast: `μ + Σ wᵢ (hᵢ − μ) / √(Σ wᵢ²)` around the canopy's
//! mean `μ`; with one weight it is the plain value. Heights are clamped at 0.
//!
//! Invariant: a pure function of the weights and values, so two tiles that
//! evaluate the same fields with the same weights agree bitwise.

/// The variance-preserving blend of `(weight, height)` pairs around `mean`
/// (weights ≥ 0, not all 0); never below 0.
#[inline]
pub fn blend(parts: &[(f32, f32)], mean: f32) -> f32 {
    let (mut sum, mut norm) = (0.0f32, 0.0f32);
    for &(w, h) in parts.iter().filter(|p| p.0 > 0.0) {
        sum += w * (h - mean);
        norm += w * w;
    }
    if norm > 0.0 { (mean + sum / norm.sqrt()).max(0.0) } else { mean }
}

/// Smoothstep of `t` clamped to `[0, 1]`.
#[inline]
pub fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_part_is_itself_and_halves_keep_their_contrast() {
        assert_eq!(blend(&[(1.0, 12.5), (0.0, 40.0)], 15.0), 12.5);
        // Independent deviations keep their spread (the operator assumes
        // uncorrelated inputs, so equal ones are raised by √2); opposite
        // deviations cancel.
        assert!((blend(&[(0.5, 25.0), (0.5, 25.0)], 15.0) - 29.142).abs() < 1e-3);
        assert_eq!(blend(&[(0.5, 5.0), (0.5, 25.0)], 15.0), 15.0);
        assert_eq!(blend(&[(0.5, 0.0), (0.5, 0.0)], 15.0), 0.0);
    }
}
