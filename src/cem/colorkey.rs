//! Colour keys in a perceptual colour space: map pixels are converted from
//! sRGB to CIE L*a*b* (D65) and matched to the nearest key within its
//! tolerance, measured as the CIE76 distance ΔE*ab (≈ 2.3 is a just noticeable
//! difference; scanned map greens vary by 10–20).

use super::surface::SurfaceType;
use serde::{Deserialize, Serialize};

/// A key colour, its tolerance and the surface it marks.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ColorKey {
    /// sRGB colour as `#rrggbb`.
    pub color: String,
    /// Largest ΔE*ab (CIE76) that still matches.
    pub tolerance: f32,
    /// The surface pixels of this colour show.
    pub surface: SurfaceType,
}

/// A key ready for matching.
#[derive(Clone, Copy, Debug)]
pub struct LabKey {
    lab: [f32; 3],
    tolerance_sq: f32,
    /// The surface this key marks.
    pub surface: SurfaceType,
}

impl ColorKey {
    /// Parses the colour; the error names what is wrong.
    pub fn compile(&self) -> Result<LabKey, String> {
        let rgb = parse_hex(&self.color).ok_or_else(|| format!("colour {:?} is not #rrggbb", self.color))?;
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) {
            return Err(format!("tolerance of {} must be a positive number", self.color));
        }
        Ok(LabKey {
            lab: srgb_to_lab(rgb.map(f32::from)),
            tolerance_sq: self.tolerance * self.tolerance,
            surface: self.surface,
        })
    }
}

/// `#rrggbb` → bytes.
pub fn parse_hex(text: &str) -> Option<[u8; 3]> {
    let hex = text.strip_prefix('#')?;
    if hex.len() != 6 || !hex.is_ascii() {
        return None;
    }
    let byte = |i: usize| u8::from_str_radix(&hex[i..i + 2], 16).ok();
    Some([byte(0)?, byte(2)?, byte(4)?])
}

/// The surface of the nearest key within tolerance, if any.
pub fn classify(rgb: [f32; 3], keys: &[LabKey]) -> Option<SurfaceType> {
    if rgb.iter().any(|v| v.is_nan()) {
        return None;
    }
    let lab = srgb_to_lab(rgb);
    keys.iter()
        .map(|k| (distance_sq(lab, k.lab), k))
        .filter(|(d, k)| *d <= k.tolerance_sq)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, k)| k.surface)
}

fn distance_sq(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// sRGB (0–255) → CIE L*a*b* with the D65 white point.
pub fn srgb_to_lab(rgb: [f32; 3]) -> [f32; 3] {
    let lin = rgb.map(|v| {
        let c = (v / 255.0).clamp(0.0, 1.0);
        if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
    });
    let x = (0.4124 * lin[0] + 0.3576 * lin[1] + 0.1805 * lin[2]) / 0.95047;
    let y = 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2];
    let z = (0.0193 * lin[0] + 0.1192 * lin[1] + 0.9505 * lin[2]) / 1.08883;
    let f = |t: f32| if t > 0.008856 { t.cbrt() } else { 7.787 * t + 16.0 / 116.0 };
    let (fx, fy, fz) = (f(x), f(y), f(z));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lab_of_reference_colours() {
        let white = srgb_to_lab([255.0; 3]);
        assert!((white[0] - 100.0).abs() < 0.1 && white[1].abs() < 0.1 && white[2].abs() < 0.1);
        let red = srgb_to_lab([255.0, 0.0, 0.0]);
        // Published L*a*b* of sRGB red: 53.24, 80.09, 67.20.
        assert!((red[0] - 53.24).abs() < 0.1 && (red[1] - 80.09).abs() < 0.2 && (red[2] - 67.20).abs() < 0.2);
    }

    #[test]
    fn the_nearest_key_within_tolerance_wins() {
        let keys: Vec<LabKey> = [("#c5e3a5", 12.0, SurfaceType::Forest), ("#a0cdf0", 12.0, SurfaceType::Water)]
            .iter()
            .map(|(c, t, s)| ColorKey { color: c.to_string(), tolerance: *t, surface: *s }.compile().unwrap())
            .collect();
        assert_eq!(classify([200.0, 225.0, 168.0], &keys), Some(SurfaceType::Forest));
        assert_eq!(classify([160.0, 204.0, 238.0], &keys), Some(SurfaceType::Water));
        assert_eq!(classify([180.0, 120.0, 60.0], &keys), None);
        assert_eq!(classify([f32::NAN, 0.0, 0.0], &keys), None);
        assert!(ColorKey { color: "c5e3a5".into(), tolerance: 1.0, surface: SurfaceType::Forest }.compile().is_err());
    }
}
