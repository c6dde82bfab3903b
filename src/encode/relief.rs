//! The shaded-relief preview, for people in QGIS and web maps: the map's
//! colours (or a colour per surface class) shaded by the combined elevation
//! map, so canopy and terrain both show, as an RGBA PNG.
//!
//! Shading is Horn's gradient with light from the north-west, 45° up; it
//! needs one sample of margin around the image. Each row is shaded with its
//! own ground spacing (east–west distances shrink with latitude), so images
//! that share a row, such as north–south neighbouring tiles, shade it alike.

use super::EncodeError;
use crate::cem::surface::{NODATA, SurfaceType};
use crate::raster::Raster;

/// What the preview is made from.
pub struct Relief<'a> {
    /// CEM heights with one extra sample on every side.
    pub cem: &'a Raster<f32>,
    /// Surface classes of the image's samples.
    pub surface: &'a Raster<u8>,
    /// The map's R, G, B at the image's samples, if the region has a map.
    pub map: Option<&'a [Raster<f32>]>,
    /// Ground distance between columns and between rows at each of the
    /// image's rows, metres (east–west distances shrink with latitude).
    pub spacing_m: &'a [(f64, f64)],
}

/// A sample's unshaded colour (0–255): the map's where it has one, else
/// its surface class's.
pub fn base_colour(class: u8, map: Option<[f32; 3]>) -> [f32; 3] {
    match map {
        Some(rgb) if rgb.iter().all(|v| v.is_finite()) => rgb,
        _ => class_colour(class),
    }
}

/// Unshaded colour of every sample (the map's, else its class's), alpha
/// 0 where there is no data: the `colour` layer and the renderer's texture.
pub fn base_colours(surface: &Raster<u8>, map: Option<&[Raster<f32>]>) -> Vec<[u8; 4]> {
    let w = surface.width();
    surface
        .data()
        .iter()
        .enumerate()
        .map(|(k, &class)| {
            if class == NODATA {
                return [0; 4];
            }
            let rgb = map.map(|bands| [0, 1, 2].map(|b| bands[b].get(k % w, k / w)));
            let c = base_colour(class, rgb).map(|v| v.round().clamp(0.0, 255.0) as u8);
            [c[0], c[1], c[2], 255]
        })
        .collect()
}

/// [`base_colours`] as an RGBA PNG.
pub fn encode_colours(surface: &Raster<u8>, map: Option<&[Raster<f32>]>) -> Result<Vec<u8>, EncodeError> {
    let rgba: Vec<u8> = base_colours(surface, map).into_iter().flatten().collect();
    super::png(&rgba, surface.width(), surface.height(), image::ExtendedColorType::Rgba8)
}

/// Colours of surface classes when there is no map.
pub fn class_colour(class: u8) -> [f32; 3] {
    match SurfaceType::from_id(class) {
        Some(SurfaceType::Forest) => [96.0, 140.0, 80.0],
        Some(SurfaceType::Water) => [120.0, 170.0, 220.0],
        Some(SurfaceType::Rock) => [205.0, 200.0, 190.0],
        Some(SurfaceType::Ice) => [245.0, 248.0, 252.0],
        Some(SurfaceType::Built) => [200.0, 150.0, 140.0],
        _ => [215.0, 215.0, 175.0],
    }
}

/// The shade of level ground (the light is 45° up).
pub const LEVEL_SHADE: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// Renders the preview as an RGBA PNG; nodata is transparent.
pub fn encode(r: &Relief) -> Result<Vec<u8>, EncodeError> {
    let (w, h) = (r.surface.width(), r.surface.height());
    if r.spacing_m.len() != h {
        return Err(EncodeError(format!("{} row spacings for {h} rows", r.spacing_m.len())));
    }
    let mut rgba = Vec::with_capacity(4 * w * h);
    for y in 0..h {
        for x in 0..w {
            let class = r.surface.get(x, y);
            let shade = shade(r.cem, x + 1, y + 1, r.spacing_m[y]);
            if class == NODATA || shade.is_nan() {
                rgba.extend_from_slice(&[0, 0, 0, 0]);
                continue;
            }
            // The map's colour where it has one, else the class's.
            let base = base_colour(class, r.map.map(|bands| [0, 1, 2].map(|b| bands[b].get(x, y))));
            let c = lit(class, base, shade);
            rgba.extend_from_slice(&[c[0], c[1], c[2], 255]);
        }
    }
    super::png(&rgba, w, h, image::ExtendedColorType::Rgba8)
}

/// The preview's colour of a sample of `class` and unshaded colour `base`
/// under `shade` (0 facing away from the light, 1 facing it): canopy reads
/// darker and greener, as forest does from the air.
pub fn lit(class: u8, base: [f32; 3], shade: f32) -> [u8; 3] {
    let tint = if class == SurfaceType::Forest as u8 { [0.8, 0.9, 0.75] } else { [1.0; 3] };
    let light = 0.3 + 0.7 * shade;
    [0, 1, 2].map(|k| (base[k] * tint[k] * light).clamp(0.0, 255.0) as u8)
}

/// A grey shaded relief of heights on a square grid of `cell_m` (canopy
/// height models and proxies): Horn's shade, brighter the higher
/// (`shade · (0.3 + 0.7 · h / max_m)`), so crowns stand out from gaps; the
/// outer samples are the margin of the shading, NaN is black. An 8-bit
/// greyscale PNG of `(w − 2) × (h − 2)` pixels.
pub fn grey(heights: &Raster<f32>, cell_m: f64, max_m: f32) -> Result<Vec<u8>, EncodeError> {
    let (w, h) = (heights.width().saturating_sub(2), heights.height().saturating_sub(2));
    let mut grey = Vec::with_capacity(w * h);
    for y in 1..=h {
        for x in 1..=w {
            let (v, s) = (heights.get(x, y), shade(heights, x, y, (cell_m, cell_m)));
            let level =
                if v.is_nan() || s.is_nan() { 0.0 } else { 255.0 * s * (0.3 + 0.7 * (v / max_m).clamp(0.0, 1.0)) };
            grey.push(level as u8);
        }
    }
    super::png(&grey, w, h, image::ExtendedColorType::L8)
}

/// Lambertian shade in [0, 1] at `(x, y)` of `cem` from Horn's 3×3 gradient;
/// a neighbour without data counts as level with the centre (so the edge
/// of the data is shaded, not lost), a centre without data gives NaN.
pub(super) fn shade(cem: &Raster<f32>, x: usize, y: usize, (dx, dy): (f64, f64)) -> f32 {
    let centre = cem.get(x, y);
    if centre.is_nan() {
        return f32::NAN;
    }
    let z = |i: usize, j: usize| f64::from(Some(cem.get(i, j)).filter(|v| !v.is_nan()).unwrap_or(centre));
    let gx = ((z(x + 1, y - 1) + 2.0 * z(x + 1, y) + z(x + 1, y + 1))
        - (z(x - 1, y - 1) + 2.0 * z(x - 1, y) + z(x - 1, y + 1)))
        / (8.0 * dx);
    let gy = ((z(x - 1, y + 1) + 2.0 * z(x, y + 1) + z(x + 1, y + 1))
        - (z(x - 1, y - 1) + 2.0 * z(x, y - 1) + z(x + 1, y - 1)))
        / (8.0 * dy);
    // Light from azimuth 315°, altitude 45°: direction (−½, ½, √½) with y to the south.
    let (lx, ly, lz) = (-0.5, -0.5, std::f64::consts::FRAC_1_SQRT_2);
    let n = (gx * gx + gy * gy + 1.0).sqrt();
    (((-gx * lx - gy * ly + lz) / n).clamp(0.0, 1.0)) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slopes_facing_the_light_are_brighter_and_nodata_is_transparent() {
        // Heights rising to the east: the slope faces west, towards the light.
        let rising_east = Raster::from_fn(5, 5, |x, _| x as f32 * 10.0);
        let falling_east = Raster::from_fn(5, 5, |x, _| -(x as f32) * 10.0);
        assert!(shade(&rising_east, 2, 2, (10.0, 10.0)) > shade(&falling_east, 2, 2, (10.0, 10.0)));
        let mut surface = Raster::filled(3, 3, SurfaceType::Plain as u8);
        surface.set(1, 1, NODATA);
        let png =
            encode(&Relief { cem: &rising_east, surface: &surface, map: None, spacing_m: &[(10.0, 10.0); 3] }).unwrap();
        let img = image::load_from_memory(&png).unwrap().into_rgba8();
        assert_eq!(img.get_pixel(1, 1).0[3], 0);
        assert_eq!(img.get_pixel(0, 0).0[3], 255);
    }

    #[test]
    fn level_ground_has_the_level_shade() {
        // Legends draw level ground with it.
        assert_eq!(shade(&Raster::filled(3, 3, 1234.5), 1, 1, (30.0, 20.0)), LEVEL_SHADE);
    }

    #[test]
    fn each_row_is_shaded_with_its_own_spacing() {
        // The same westward slope, closer columns on row 0: steeper, so brighter.
        let rising_east = Raster::from_fn(4, 4, |x, _| x as f32 * 10.0);
        let surface = Raster::filled(2, 2, SurfaceType::Plain as u8);
        let spacing_m = [(10.0, 10.0), (40.0, 10.0)];
        let png = encode(&Relief { cem: &rising_east, surface: &surface, map: None, spacing_m: &spacing_m }).unwrap();
        let img = image::load_from_memory(&png).unwrap().into_rgba8();
        let (steep, gentle) = (img.get_pixel(0, 0).0, img.get_pixel(0, 1).0);
        assert!(steep[0] > gentle[0], "{steep:?} vs {gentle:?}");
        let short = Relief { cem: &rising_east, surface: &surface, map: None, spacing_m: &spacing_m[..1] };
        assert!(encode(&short).is_err(), "a spacing for every row");
    }

    #[test]
    fn the_edge_of_the_data_is_shaded_not_lost() {
        // Data only in the middle sample and its east neighbour (rising east).
        let mut cem = Raster::filled(5, 5, f32::NAN);
        cem.set(2, 2, 100.0);
        cem.set(3, 2, 120.0);
        let lit = shade(&cem, 2, 2, (10.0, 10.0));
        assert!(lit.is_finite() && lit > shade(&Raster::filled(3, 3, 100.0), 1, 1, (10.0, 10.0)), "{lit}");
        assert!(shade(&cem, 1, 1, (10.0, 10.0)).is_nan(), "no data at the centre");
    }
}
