//! Separable Gaussian blur by direct convolution, the optional last step of the
//! vegetation cover map ("a subsequent blur would greatly diminish the remaining
//! artifacts", dissertation Figure 6.3).
//!
//! Direct convolution on purpose: each output is the same weighted sum in the
//! same order wherever the buffer starts, so blurred windows are bitwise
//! seamless. (A running-sum box blur is faster but its rounding depends on where
//! the sum started.) NaN inputs are skipped and the remaining weights
//! renormalised; a window of only NaN stays NaN.

use super::Raster;

/// Normalised Gaussian weights for a kernel of `radius` samples each side,
/// with σ = radius / 2 so that the kernel reaches 2σ.
pub fn gaussian_weights(radius: usize) -> Vec<f32> {
    let sigma = (radius as f64 / 2.0).max(0.5);
    let raw: Vec<f64> =
        (-(radius as i64)..=radius as i64).map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp()).collect();
    let total: f64 = raw.iter().sum();
    raw.iter().map(|w| (w / total) as f32).collect()
}

/// Blurs with a `(2r+1)` separable Gaussian. Samples within `radius` of the
/// buffer edge see only the buffer; callers crop a margin of `radius`.
pub fn gaussian(src: &Raster<f32>, radius: usize) -> Raster<f32> {
    if radius == 0 {
        return src.clone();
    }
    let weights = gaussian_weights(radius);
    let (w, h) = (src.width(), src.height());
    let horizontal = Raster::from_fn(w, h, |x, y| convolve(&weights, |i| tap(src.row(y), x, i, radius)));
    Raster::from_fn(w, h, |x, y| {
        convolve(&weights, |i| {
            let sy = y as i64 + i as i64 - radius as i64;
            if sy >= 0 && (sy as usize) < h { horizontal.get(x, sy as usize) } else { f32::NAN }
        })
    })
}

fn tap(row: &[f32], x: usize, i: usize, radius: usize) -> f32 {
    let sx = x as i64 + i as i64 - radius as i64;
    if sx >= 0 && (sx as usize) < row.len() { row[sx as usize] } else { f32::NAN }
}

fn convolve(weights: &[f32], value: impl Fn(usize) -> f32) -> f32 {
    let (mut sum, mut weight) = (0.0f32, 0.0f32);
    for (i, &wt) in weights.iter().enumerate() {
        let v = value(i);
        if !v.is_nan() {
            sum += wt * v;
            weight += wt;
        }
    }
    if weight > 0.0 { sum / weight } else { f32::NAN }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_are_symmetric_and_sum_to_one() {
        let w = gaussian_weights(4);
        assert_eq!(w.len(), 9);
        assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert_eq!(w[0], w[8]);
        assert!(w[4] > w[3]);
    }

    #[test]
    fn constant_stays_constant_and_a_step_becomes_a_ramp() {
        let flat = Raster::filled(7, 7, 0.5);
        assert!(gaussian(&flat, 2).data().iter().all(|&v| (v - 0.5).abs() < 1e-6));
        let step = Raster::from_fn(9, 1, |x, _| if x < 4 { 0.0 } else { 1.0 });
        let blurred = gaussian(&step, 2);
        let row = blurred.row(0);
        assert!(row.windows(2).all(|p| p[0] <= p[1]));
        assert!(row[3] > 0.0 && row[4] < 1.0);
    }

    #[test]
    fn a_window_is_bitwise_equal_to_the_same_window_of_a_larger_buffer() {
        let big = Raster::from_fn(30, 30, |x, y| ((x * 7 + y * 13) % 11) as f32 / 11.0);
        let whole = gaussian(&big, 3);
        let part = gaussian(&big.crop(crate::raster::Window::new(5, 6, 20, 18), f32::NAN), 3);
        for y in 3..15 {
            for x in 3..17 {
                assert_eq!(part.get(x, y).to_bits(), whole.get(x + 5, y + 6).to_bits());
            }
        }
    }
}
