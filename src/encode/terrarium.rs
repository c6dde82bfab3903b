//! Terrarium-encoded heights (the Mapzen/AWS terrain tiles format that
//! MapLibre, Tangram and deck.gl read): an 8-bit RGB PNG where
//! `h = R·256 + G + B/256 − 32768` metres, about 4 mm steps. Nodata is
//! black (−32768 m).

use super::EncodeError;
use crate::raster::Raster;

/// Encodes heights as a Terrarium PNG.
pub fn encode(heights: &Raster<f32>) -> Result<Vec<u8>, EncodeError> {
    let mut rgb = Vec::with_capacity(3 * heights.data().len());
    for &h in heights.data() {
        rgb.extend_from_slice(&pixel(h));
    }
    super::png(&rgb, heights.width(), heights.height(), image::ExtendedColorType::Rgb8)
}

/// The RGB of one height (clamped to the encodable −32768 … 32767.996 m).
pub fn pixel(h: f32) -> [u8; 3] {
    if h.is_nan() {
        return [0, 0, 0];
    }
    let v = (f64::from(h) + 32768.0).clamp(0.0, 65535.0 + 255.0 / 256.0);
    let whole = v.floor();
    let frac = ((v - whole) * 256.0).floor().min(255.0);
    [(whole / 256.0).floor() as u8, (whole % 256.0) as u8, frac as u8]
}

/// The height of one RGB.
pub fn height(rgb: [u8; 3]) -> f64 {
    f64::from(rgb[0]) * 256.0 + f64::from(rgb[1]) + f64::from(rgb[2]) / 256.0 - 32768.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heights_round_trip_within_a_step() {
        for h in [-430.25f32, 0.0, 1234.567, 8850.0] {
            let back = height(pixel(h));
            assert!((back - f64::from(h)).abs() < 1.0 / 256.0, "{h} -> {back}");
        }
        assert_eq!(pixel(f32::NAN), [0, 0, 0]);
        assert_eq!(pixel(0.0), [128, 0, 0]);
    }
}
