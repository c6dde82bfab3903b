//! Blending canopy heights without washing them out.
//!
//! A plain weighted mean of two unrelated canopies halves their contrast
//! where both weigh ½: crowns become low mounds and gaps shallow pits. The
//! variance-preserving blend of Heitz and Neyret ("High-performance
//! by-example noise using a histogram-preserving blending operator", 2018)
//! keeps the contrast: `μ + Σ wᵢ (hᵢ − μ) / √(Σ wᵢ²)` around the mean `μ`;
//! with one weight it is the plain value. For Gaussian inputs it keeps the
//! whole distribution, so tile sets blend in [`Gaussian`] space: heights are
//! mapped through the CHM's distribution function onto a standard normal,
//! blended there, and mapped back.
//!
//! Invariant: pure functions, so two tiles that evaluate the same fields
//! with the same weights agree bitwise.

/// The variance-preserving blend of `(weight, value)` pairs around `mean`
/// (weights ≥ 0, not all 0).
#[inline]
pub fn blend(parts: &[(f32, f32)], mean: f32) -> f32 {
    let (mut sum, mut norm) = (0.0f32, 0.0f32);
    for &(w, h) in parts.iter().filter(|p| p.0 > 0.0) {
        sum += w * (h - mean);
        norm += w * w;
    }
    if norm > 0.0 { mean + sum / norm.sqrt() } else { mean }
}

/// Smoothstep of `t` clamped to `[0, 1]`.
#[inline]
pub fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// A height distribution and its map onto the standard normal one
/// (`Φ⁻¹(F(h))`, ties at their middle rank) and back.
pub struct Gaussian {
    sorted: Vec<f32>,
}

impl Gaussian {
    /// The distribution of `sorted` (ascending, no NaN, not empty).
    pub fn new(sorted: Vec<f32>) -> Gaussian {
        Gaussian { sorted }
    }

    /// Height → normal score.
    pub fn forward(&self, h: f32) -> f32 {
        let n = self.sorted.len() as f64;
        let below = self.sorted.partition_point(|&v| v < h) as f64;
        let up_to = self.sorted.partition_point(|&v| v <= h) as f64;
        let p = (0.5 * (below + up_to) / n).clamp(0.5 / n, 1.0 - 0.5 / n);
        inverse_normal_cdf(p) as f32
    }

    /// Normal score → height, interpolated between the sorted heights.
    pub fn back(&self, g: f32) -> f32 {
        let n = self.sorted.len();
        let at = (normal_cdf(f64::from(g)) * n as f64 - 0.5).clamp(0.0, (n - 1) as f64);
        let i = at.floor() as usize;
        let (a, b) = (self.sorted[i], self.sorted[(i + 1).min(n - 1)]);
        a + (b - a) * (at - i as f64) as f32
    }
}

/// Φ(x), the standard normal distribution function (Abramowitz and Stegun
/// 7.1.26 for erfc, |error| < 1.5e-7).
pub fn normal_cdf(x: f64) -> f64 {
    let z = x.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * z);
    let poly =
        t * (0.254_829_592 + t * (-0.284_496_736 + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let tail = 0.5 * poly * (-z * z).exp();
    if x >= 0.0 { 1.0 - tail } else { tail }
}

/// Φ⁻¹(p) for p in (0, 1) (Acklam's rational approximation, relative error
/// < 1.2e-9).
pub fn inverse_normal_cdf(p: f64) -> f64 {
    const A: [f64; 6] = [
        -39.696_830_286_653_76,
        220.946_098_424_520_5,
        -275.928_510_446_968_7,
        138.357_751_867_269,
        -30.664_798_066_147_16,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -54.476_098_798_224_06,
        161.585_836_858_040_9,
        -155.698_979_859_886_6,
        66.801_311_887_719_72,
        -13.280_681_552_885_72,
    ];
    const C: [f64; 6] = [
        -0.007_784_894_002_430_293,
        -0.322_396_458_041_136_5,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] =
        [0.007_784_695_709_041_462, 0.322_467_129_070_039_8, 2.445_134_137_142_996, 3.754_408_661_907_416];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    if p < 0.024_25 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.024_25 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
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
    }

    #[test]
    fn the_normal_maps_invert_each_other_and_heights_round_trip() {
        // Φ is good to 1.5e-7 absolute (Abramowitz and Stegun 7.1.26).
        for p in [1e-6, 0.01, 0.2, 0.5, 0.77, 0.99, 0.999_99] {
            assert!((normal_cdf(inverse_normal_cdf(p)) - p).abs() < 1.5e-7, "{p}");
        }
        assert!((inverse_normal_cdf(0.975) - 1.959_963_985).abs() < 1e-8);
        let g = Gaussian::new(vec![0.0, 0.0, 1.0, 2.5, 7.0, 30.0]);
        for h in [0.0, 1.0, 2.5, 7.0, 30.0] {
            assert!((g.back(g.forward(h)) - h).abs() < 1e-4, "{h}");
        }
        assert!(g.forward(0.0) < g.forward(1.0) && g.back(-9.0) == 0.0 && g.back(9.0) == 30.0);
    }
}
