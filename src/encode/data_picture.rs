//! Data layers drawn as pictures, for clients that ask for a data layer in
//! a picture format (JPEG: GDAL's WMS driver asks for it unless told
//! otherwise). The picture is for looking at; the data formats carry the
//! values. Heights (`dem`, `cem`, `max4`, `max32`) are shaded grey, as the
//! relief preview shades (Horn's gradient, light from the north-west), so
//! tiles need no common range and neighbours agree; the canopy is grey
//! from black (none) to white at [`CANOPY_WHITE_M`] and taller; the cover
//! from black (none) to white (full); surface classes take the relief's
//! class colours. No data is transparent.
//!
//! Heights come with one sample of margin on every side, for the shading;
//! so do the other layers, for one calling convention.

use super::EncodeError;
use super::relief::{class_colour, shade};
use crate::cem::surface::NODATA;
use crate::cem::{Layer, LayerSamples};
use crate::raster::Raster;

/// Canopy height drawn white, metres (taller is white too): a tall forest.
pub const CANOPY_WHITE_M: f32 = 30.0;

/// `layer`'s samples (with one sample of margin on every side) as an RGBA
/// PNG of the inner samples; `spacing_m` gives each inner row's ground
/// distance between columns and between rows.
pub fn encode(layer: Layer, samples: &LayerSamples, spacing_m: &[(f64, f64)]) -> Result<Vec<u8>, EncodeError> {
    let (w, h) = match samples {
        LayerSamples::Float(r) => (r.width(), r.height()),
        LayerSamples::Class(r) => (r.width(), r.height()),
    };
    let (w, h) = (w.saturating_sub(2), h.saturating_sub(2));
    if spacing_m.len() != h {
        return Err(EncodeError(format!("{} row spacings for {h} rows", spacing_m.len())));
    }
    let mut rgba = Vec::with_capacity(4 * w * h);
    for (y, &spacing) in spacing_m.iter().enumerate() {
        for x in 0..w {
            let pixel = match samples {
                LayerSamples::Class(r) => class_pixel(r.get(x + 1, y + 1)),
                LayerSamples::Float(r) => grey_pixel(layer, r, (x + 1, y + 1), spacing),
            };
            rgba.extend_from_slice(&pixel);
        }
    }
    super::png(&rgba, w, h, image::ExtendedColorType::Rgba8)
}

/// A surface class's colour, transparent for no data.
fn class_pixel(class: u8) -> [u8; 4] {
    if class == NODATA {
        return [0; 4];
    }
    let c = class_colour(class).map(|v| v as u8);
    [c[0], c[1], c[2], 255]
}

/// The grey (0 black to 1 white) a cover or canopy value `v` is drawn in;
/// `None` for heights, which are shaded instead.
pub fn value_grey(layer: Layer, v: f32) -> Option<f32> {
    match layer {
        Layer::Cover => Some(v),
        Layer::Canopy => Some(v / CANOPY_WHITE_M),
        _ => None,
    }
}

/// The grey of a continuous layer's sample at `(x, y)` (margin included),
/// transparent for no data.
fn grey_pixel(layer: Layer, r: &Raster<f32>, (x, y): (usize, usize), spacing: (f64, f64)) -> [u8; 4] {
    let level = value_grey(layer, r.get(x, y)).unwrap_or_else(|| shade(r, x, y, spacing));
    if level.is_nan() {
        return [0; 4];
    }
    let g = (255.0 * level.clamp(0.0, 1.0)).round() as u8;
    [g, g, g, 255]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode(png: &[u8]) -> image::RgbaImage {
        image::load_from_memory(png).expect("a PNG").into_rgba8()
    }

    #[test]
    fn heights_are_shaded_and_nodata_is_transparent() {
        // A 45° slope facing east, lit from the north-west, with a hole.
        let mut r = Raster::from_fn(6, 5, |x, _| 100.0 * (5 - x) as f32);
        r.set(3, 2, f32::NAN);
        let png = encode(Layer::Dem, &LayerSamples::Float(r), &[(100.0, 100.0); 3]).unwrap();
        let img = decode(&png);
        assert_eq!(img.dimensions(), (4, 3));
        // Turned from the light: (sin 45° − ½) / √2 of full light.
        assert_eq!(img.get_pixel(0, 0).0, [37, 37, 37, 255]);
        assert_eq!(img.get_pixel(2, 1).0, [0; 4]);
        // Flat ground is lit as the light's elevation allows: sin 45°.
        let flat = encode(Layer::Cem, &LayerSamples::Float(Raster::filled(3, 3, 7.0)), &[(30.0, 30.0)]).unwrap();
        assert_eq!(decode(&flat).get_pixel(0, 0).0, [180, 180, 180, 255]);
    }

    #[test]
    fn cover_is_grey_from_black_to_white_and_classes_take_their_colours() {
        let cover = Raster::from_fn(4, 3, |x, _| x as f32 / 3.0);
        let img = decode(&encode(Layer::Cover, &LayerSamples::Float(cover), &[(1.0, 1.0)]).unwrap());
        assert_eq!((img.get_pixel(0, 0).0, img.get_pixel(1, 0).0), ([85, 85, 85, 255], [170, 170, 170, 255]));
        let classes = Raster::from_fn(4, 3, |x, _| if x == 1 { 2 } else { NODATA });
        let img = decode(&encode(Layer::Surface, &LayerSamples::Class(classes), &[(1.0, 1.0)]).unwrap());
        assert_eq!((img.get_pixel(0, 0).0, img.get_pixel(1, 0).0), ([120, 170, 220, 255], [0; 4]));
    }

    #[test]
    fn taller_canopy_is_brighter() {
        let flat = |h: f32| encode(Layer::Canopy, &LayerSamples::Float(Raster::filled(3, 3, h)), &[(1.0, 1.0)]);
        let grey = |h: f32| decode(&flat(h).unwrap()).get_pixel(0, 0).0[0];
        assert_eq!([0.0, 15.0, 30.0, 45.0].map(grey), [0, 128, 255, 255]);
        assert!(encode(Layer::Canopy, &LayerSamples::Float(Raster::filled(3, 3, 1.0)), &[]).is_err());
    }
}
