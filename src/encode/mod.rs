//! Tile encodings: raw BIL (16-bit integer, 32-bit float; little-endian,
//! exactly width × height samples, row 0 north, as World Wind expects),
//! 16-bit greyscale PNG, and float32 GeoTIFF; for web clients Terrarium PNG
//! ([`terrarium`]) and Cesium's heightmap terrain ([`heightmap`]).
//!
//! Heights are `f32` metres inside Sylva. 16-bit encodings state how to read
//! them back: `h = offset + scale · v` (see [`Quantization`]); values outside
//! the encodable range are clamped and counted in [`Encoded::clamped`], so the
//! error is stated, not hidden. Nodata (NaN) never reaches a file as NaN: it
//! becomes the format's nodata value.

pub mod data_picture;
pub mod geotiff;
pub mod heightmap;
pub mod relief;
pub mod terrarium;

use crate::cem::Layer;
use crate::grid::SampleGrid;
use crate::raster::Raster;
use serde::{Deserialize, Serialize};
use std::ops::RangeInclusive;
use thiserror::Error;

/// Nodata of BIL16 heights and of float outputs (World Wind's missing-data value).
pub const NODATA_HEIGHT: f32 = -32768.0;

/// Tile formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// Little-endian `i16`.
    Bil16,
    /// Little-endian `f32`.
    Bil32,
    /// 16-bit greyscale PNG.
    Png16,
    /// Float32 (or 8-bit for surface classes) GeoTIFF, EPSG:4326.
    Tiff,
}

impl Format {
    /// Parses `bil16`, `bil32`, `png16` or `tiff`.
    pub fn parse(text: &str) -> Option<Format> {
        match text.to_ascii_lowercase().as_str() {
            "bil16" => Some(Format::Bil16),
            "bil32" => Some(Format::Bil32),
            "png16" => Some(Format::Png16),
            "tiff" | "tif" => Some(Format::Tiff),
            _ => None,
        }
    }

    /// The name [`Format::parse`] reads.
    pub fn name(self) -> &'static str {
        match self {
            Format::Bil16 => "bil16",
            Format::Bil32 => "bil32",
            Format::Png16 => "png16",
            Format::Tiff => "tiff",
        }
    }

    /// MIME type.
    pub fn mime(self) -> &'static str {
        match self {
            Format::Bil16 => "application/bil16",
            Format::Bil32 => "application/bil32",
            Format::Png16 => "image/png",
            Format::Tiff => "image/tiff",
        }
    }
}

/// A 16-bit code `v` stands for `offset + scale · v`; `nodata` is the code of
/// missing samples.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Quantization {
    /// Value of code 0.
    pub offset: f64,
    /// Value step per code.
    pub scale: f64,
}

impl Quantization {
    /// Heights in PNG16 by default: −500 m to 9,330 m in 15 cm steps (the
    /// Dead Sea to above Everest; half a step is 7.5 cm), code 0 is nodata.
    pub const PNG16_HEIGHTS: Quantization = Quantization { offset: -500.15, scale: 0.15 };
    /// BIL16 heights: whole metres, as World Wind reads them.
    pub const BIL16_HEIGHTS: Quantization = Quantization { offset: 0.0, scale: 1.0 };
    /// Cover fractions in PNG16.
    pub const PNG16_COVER: Quantization = Quantization { offset: 0.0, scale: 1.0 / 65535.0 };
    /// Cover fractions in BIL16: basis points.
    pub const BIL16_COVER: Quantization = Quantization { offset: 0.0, scale: 1.0 / 10000.0 };
    /// Class ids as they are.
    pub const IDS: Quantization = Quantization { offset: 0.0, scale: 1.0 };

    /// The code for `value`, clamped into `lo..=hi` (`nodata` for NaN); the
    /// flag says a number was clamped. Branch-free, so loops over it are
    /// vectorized.
    #[inline]
    fn code(&self, value: f32, lo: f64, hi: f64, nodata: i32) -> (i32, bool) {
        let v = ((value as f64 - self.offset) / self.scale).round();
        // max/min take the number when `v` is NaN; the select below drops it.
        let c = v.max(lo).min(hi);
        let nan = value.is_nan();
        (if nan { nodata } else { whole_to_i32(c) }, !nan & (c != v))
    }
}

/// `c` (a whole number of magnitude below 2³¹) as an integer. Adding
/// 1.5 · 2⁵² puts it in the low bits of the mantissa, exactly; unlike
/// `c as i32`, which checks for NaN and saturates one sample at a time, this
/// is vectorized.
#[inline]
fn whole_to_i32(c: f64) -> i32 {
    const SHIFT: f64 = 6_755_399_441_055_744.0;
    (c + SHIFT).to_bits() as u32 as i32
}

/// A tile's samples: heights/cover as `f32`, or surface class ids.
#[derive(Clone, Copy, Debug)]
pub enum Samples<'a> {
    /// Continuous values, NaN = nodata.
    Float(&'a Raster<f32>),
    /// Class ids, 255 = nodata.
    Class(&'a Raster<u8>),
}

impl Samples<'_> {
    /// True when no sample holds data.
    pub fn all_nodata(&self) -> bool {
        match self {
            Samples::Float(r) => r.all_nodata(),
            Samples::Class(r) => r.data().iter().all(|&c| c == crate::cem::surface::NODATA),
        }
    }

    fn width(&self) -> usize {
        match self {
            Samples::Float(r) => r.width(),
            Samples::Class(r) => r.width(),
        }
    }

    /// The samples as `f32` (class ids converted as they are, 255 included).
    fn floats(&self) -> std::borrow::Cow<'_, [f32]> {
        match self {
            Samples::Float(r) => std::borrow::Cow::Borrowed(r.data()),
            Samples::Class(r) => r.data().iter().map(|&v| f32::from(v)).collect(),
        }
    }
}

/// An encoded tile.
#[derive(Clone, Debug)]
pub struct Encoded {
    /// The file's bytes.
    pub bytes: Vec<u8>,
    /// Samples that did not fit the 16-bit range and were clamped.
    pub clamped: usize,
    /// How to read 16-bit codes back, for 16-bit formats.
    pub quantization: Option<Quantization>,
}

/// The encoding failed (only I/O inside the encoders can fail).
#[derive(Debug, Error)]
#[error("encoding failed: {0}")]
pub struct EncodeError(pub String);

/// The 16-bit quantizations of a layer: (BIL16, PNG16).
pub fn quantizations(layer: Layer, png16_heights: Quantization) -> (Quantization, Quantization) {
    match layer {
        Layer::Cover => (Quantization::BIL16_COVER, Quantization::PNG16_COVER),
        Layer::Surface => (Quantization::IDS, Quantization::IDS),
        _ => (Quantization::BIL16_HEIGHTS, png16_heights),
    }
}

/// Encodes one layer of a tile.
pub fn encode(
    layer: Layer,
    samples: Samples,
    grid: &SampleGrid,
    format: Format,
    png16_heights: Quantization,
) -> Result<Encoded, EncodeError> {
    let (bil16_q, png16_q) = quantizations(layer, png16_heights);
    match format {
        Format::Bil16 => Ok(bil16(samples, bil16_q)),
        Format::Bil32 => Ok(Encoded { bytes: bil32(samples), clamped: 0, quantization: None }),
        // Code 0 is nodata for heights; cover and classes use every code.
        Format::Png16 => png16(samples, png16_q, !matches!(layer, Layer::Cover | Layer::Surface)),
        Format::Tiff => Ok(Encoded { bytes: geotiff::write(samples, grid)?, clamped: 0, quantization: None }),
    }
}

fn bil16(samples: Samples, q: Quantization) -> Encoded {
    let lo = i32::from(i16::MIN) + 1;
    let (bytes, clamped) =
        quantize(&samples.floats(), q, NODATA_HEIGHT as i32, lo..=i32::from(i16::MAX), |c| (c as i16).to_le_bytes());
    Encoded { bytes, clamped, quantization: Some(q) }
}

fn bil32(samples: Samples) -> Vec<u8> {
    let floats = samples.floats();
    let mut bytes = Vec::with_capacity(4 * floats.len());
    for &v in floats.iter() {
        bytes.extend_from_slice(&(if v.is_nan() { NODATA_HEIGHT } else { v }).to_le_bytes());
    }
    bytes
}

/// The 16-bit codes of `values` as bytes (`to_bytes` picks the byte order):
/// `nodata` for NaN, others clamped into `codes`; and how many were clamped.
fn quantize(
    values: &[f32],
    q: Quantization,
    nodata: i32,
    codes: RangeInclusive<i32>,
    to_bytes: impl Fn(i32) -> [u8; 2],
) -> (Vec<u8>, usize) {
    let (lo, hi) = (f64::from(*codes.start()), f64::from(*codes.end()));
    let mut clamped = 0;
    let mut bytes = vec![0u8; 2 * values.len()];
    // Codes a run at a time into a buffer, then bytes: the first loop is
    // vectorized (written straight to bytes, it was not).
    let mut run = [0i32; 256];
    for (out, values) in bytes.chunks_mut(2 * run.len()).zip(values.chunks(run.len())) {
        for (c, &v) in run.iter_mut().zip(values) {
            let (code, was) = q.code(v, lo, hi, nodata);
            clamped += usize::from(was);
            *c = code;
        }
        for (o, &c) in out.chunks_exact_mut(2).zip(&run) {
            o.copy_from_slice(&to_bytes(c));
        }
    }
    (bytes, clamped)
}

/// PNG16: when `zero_is_nodata`, valid samples use codes 1..=65535.
fn png16(samples: Samples, q: Quantization, zero_is_nodata: bool) -> Result<Encoded, EncodeError> {
    // The image crate takes 16-bit samples in native byte order.
    let (bytes, clamped) =
        quantize(&samples.floats(), q, 0, i32::from(zero_is_nodata)..=65535, |c| (c as u16).to_ne_bytes());
    let (w, h) = (samples.width(), bytes.len() / 2 / samples.width().max(1));
    Ok(Encoded { bytes: png(&bytes, w, h, image::ExtendedColorType::L16)?, clamped, quantization: Some(q) })
}

/// A PNG of `w × h` pixels of `color` (16-bit samples in native byte order),
/// fast deflate with Paeth filtering: what every PNG Sylva writes uses.
pub fn png(pixels: &[u8], w: usize, h: usize, color: image::ExtendedColorType) -> Result<Vec<u8>, EncodeError> {
    let mut out = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Paeth,
    );
    image::ImageEncoder::write_image(encoder, pixels, w as u32, h as u32, color)
        .map_err(|e| EncodeError(e.to_string()))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{BBox, TileGrid};

    fn grid(w: usize, h: usize) -> SampleGrid {
        BBox::parse("10,46,10.1,46.1").unwrap().point_grid(w, h, &TileGrid::new(36.0, 513).unwrap()).unwrap()
    }

    #[test]
    fn codes_are_rounded_and_clamped_as_f64_arithmetic_says() {
        let q = Quantization::PNG16_HEIGHTS;
        let reference = |v: f32| {
            let x = ((v as f64 - q.offset) / q.scale).round();
            (x.clamp(1.0, 65535.0) as i32, x.clamp(1.0, 65535.0) != x)
        };
        let mut state = 0x9E37_79B9u32;
        let mut values = vec![f32::INFINITY, f32::NEG_INFINITY, -500.075, -500.0751, 9330.0, 9330.08, 1e30];
        values.extend((0..10_000).map(|_| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state as f32 / u32::MAX as f32) * 11_000.0 - 1_000.0
        }));
        for v in values {
            assert_eq!(q.code(v, 1.0, 65535.0, 0), reference(v), "{v}");
        }
        assert_eq!(q.code(f32::NAN, 1.0, 65535.0, 0), (0, false));
        for c in [i32::MIN + 1, -32768, -1, 0, 1, 65535, i32::MAX] {
            assert_eq!(whole_to_i32(f64::from(c)), c);
        }
    }

    #[test]
    fn bil_has_exactly_one_sample_per_grid_point_and_states_clamping() {
        let r = Raster::from_vec(3, 2, vec![-430.4, 8850.6, f32::NAN, 40000.0, 0.0, -1.0]).unwrap();
        let e =
            encode(Layer::Cem, Samples::Float(&r), &grid(3, 2), Format::Bil16, Quantization::PNG16_HEIGHTS).unwrap();
        assert_eq!(e.bytes.len(), 3 * 2 * 2);
        let v: Vec<i16> = e.bytes.chunks(2).map(|b| i16::from_le_bytes([b[0], b[1]])).collect();
        assert_eq!(v, vec![-430, 8851, -32768, 32767, 0, -1]);
        assert_eq!(e.clamped, 1);
        let f =
            encode(Layer::Cem, Samples::Float(&r), &grid(3, 2), Format::Bil32, Quantization::PNG16_HEIGHTS).unwrap();
        assert_eq!(f.bytes.len(), 3 * 2 * 4);
        assert_eq!(f32::from_le_bytes(f.bytes[8..12].try_into().unwrap()), NODATA_HEIGHT);
    }

    #[test]
    fn png16_round_trips_within_half_a_step() {
        let heights = [-430.0f32, 0.0, 1234.567, 8850.0];
        let r = Raster::from_vec(2, 2, heights.to_vec()).unwrap();
        let q = Quantization::PNG16_HEIGHTS;
        let e = encode(Layer::Dem, Samples::Float(&r), &grid(2, 2), Format::Png16, q).unwrap();
        let img = image::load_from_memory(&e.bytes).unwrap().into_luma16();
        for (code, h) in img.pixels().zip(heights) {
            let back = q.offset + q.scale * code.0[0] as f64;
            assert!((back - h as f64).abs() <= q.scale / 2.0 + 1e-9, "{h} -> {back}");
        }
        assert_eq!(e.clamped, 0);
    }
}
