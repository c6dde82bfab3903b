//! How pictures (`relief`, `colour`) are answered. They are computed and
//! cached as RGBA PNGs, transparent where there is no data; a reply that asks
//! for a background (WMS 1.3.0 §7.3.3.9: `BGCOLOR`, unless `TRANSPARENT=TRUE`)
//! or for JPEG, which has no alpha and always lies on one (white unless
//! given), is laid on it as it is answered.

use crate::encode::{self, EncodeError};
use crate::server::ServeError;
use crate::server::service::{Tile, TileService};
use std::sync::Arc;
use std::time::Instant;

/// What a picture's no-data shows in JPEG when no background was asked for.
pub const WHITE: [u8; 3] = [255, 255, 255];

/// JPEG quality of pictures: shaded relief shows no blocks at 85.
const JPEG_QUALITY: u8 = 85;

/// Encodings of pictures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PictureFormat {
    /// RGBA PNG, or RGB PNG on a background.
    Png,
    /// JPEG, on a background.
    Jpeg,
}

impl PictureFormat {
    /// The MIME type answered.
    pub fn mime(self) -> &'static str {
        match self {
            PictureFormat::Png => "image/png",
            PictureFormat::Jpeg => "image/jpeg",
        }
    }

    /// The file extension of a tile in this format.
    pub fn extension(self) -> &'static str {
        match self {
            PictureFormat::Png => "png",
            PictureFormat::Jpeg => "jpg",
        }
    }

    /// The format of a tile's file extension (any case), if it is a picture's.
    pub fn of_extension(ext: &str) -> Option<PictureFormat> {
        match ext.to_ascii_lowercase().as_str() {
            "png" => Some(PictureFormat::Png),
            "jpg" | "jpeg" => Some(PictureFormat::Jpeg),
            _ => None,
        }
    }
}

/// `pixels` RGBA pixels of `background`, or transparent if none.
pub fn filled(pixels: usize, background: Option<[u8; 3]>) -> Vec<u8> {
    match background {
        Some([r, g, b]) => [r, g, b, 255].repeat(pixels),
        None => vec![0; 4 * pixels],
    }
}

/// `w × h` RGBA pixels in `format`: a transparent PNG without a
/// `background`, else laid on it (JPEG on white without one).
pub fn encode(
    rgba: &[u8],
    w: usize,
    h: usize,
    background: Option<[u8; 3]>,
    format: PictureFormat,
) -> Result<Vec<u8>, EncodeError> {
    let under = match (format, background) {
        (PictureFormat::Png, None) => return encode::png(rgba, w, h, image::ExtendedColorType::Rgba8),
        (PictureFormat::Jpeg, None) => WHITE,
        (_, Some(colour)) => colour,
    };
    let rgb = lay_on(rgba, under);
    match format {
        PictureFormat::Png => encode::png(&rgb, w, h, image::ExtendedColorType::Rgb8),
        PictureFormat::Jpeg => jpeg(&rgb, w, h),
    }
}

/// A cached RGBA PNG answered in `format` on `background` (see [`encode()`]).
pub fn reencode(png: &[u8], background: Option<[u8; 3]>, format: PictureFormat) -> Result<Vec<u8>, EncodeError> {
    let picture =
        image::load_from_memory_with_format(png, image::ImageFormat::Png).map_err(|e| EncodeError(e.to_string()))?;
    let rgba = picture.into_rgba8();
    let (w, h) = rgba.dimensions();
    encode(rgba.as_raw(), w as usize, h as usize, background, format)
}

/// A cached picture tile answered in `format` on `background`: as it is (a
/// transparent PNG, or an absent tile), else re-encoded on the compute pool
/// (503 when it is full), its time added to `Server-Timing`.
pub async fn answer(
    tiles: &TileService,
    tile: Arc<Tile>,
    background: Option<[u8; 3]>,
    format: PictureFormat,
) -> Result<Arc<Tile>, ServeError> {
    if tile.bytes.is_empty() || (format == PictureFormat::Png && background.is_none()) {
        return Ok(tile);
    }
    let png = tile.bytes.clone();
    let (bytes, took) = tiles
        .run(move |_| {
            let start = Instant::now();
            reencode(&png, background, format).map(|b| (b, start.elapsed())).map_err(ServeError::internal)
        })
        .await?;
    let timing = format!("{}, picture;dur={:.2}", tile.timing, took.as_secs_f64() * 1e3);
    Ok(Arc::new(Tile { stale: tile.stale, ..Tile::new(bytes, timing) }))
}

/// RGBA pixels composited over an opaque `background`: RGB pixels.
fn lay_on(rgba: &[u8], background: [u8; 3]) -> Vec<u8> {
    rgba.chunks_exact(4)
        .flat_map(|p| {
            let a = u16::from(p[3]);
            let over = |c: u8, under: u8| ((u16::from(c) * a + u16::from(under) * (255 - a) + 127) / 255) as u8;
            [over(p[0], background[0]), over(p[1], background[1]), over(p[2], background[2])]
        })
        .collect()
}

fn jpeg(rgb: &[u8], w: usize, h: usize) -> Result<Vec<u8>, EncodeError> {
    let mut out = Vec::new();
    let encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY);
    image::ImageEncoder::write_image(encoder, rgb, w as u32, h as u32, image::ExtendedColorType::Rgb8)
        .map_err(|e| EncodeError(e.to_string()))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Opaque red, transparent, and green at half cover.
    const RGBA: [u8; 12] = [255, 0, 0, 255, 9, 9, 9, 0, 0, 255, 0, 128];

    fn png() -> Vec<u8> {
        encode::png(&RGBA, 3, 1, image::ExtendedColorType::Rgba8).unwrap()
    }

    #[test]
    fn a_picture_is_laid_on_its_background() {
        let flat = image::load_from_memory(&reencode(&png(), Some([0, 0, 255]), PictureFormat::Png).unwrap()).unwrap();
        assert_eq!(flat.color(), image::ColorType::Rgb8);
        let px: Vec<[u8; 3]> = flat.into_rgb8().pixels().map(|p| p.0).collect();
        assert_eq!(px, vec![[255, 0, 0], [0, 0, 255], [0, 128, 127]]);
        assert!(reencode(b"not a png", Some([0, 0, 0]), PictureFormat::Png).is_err());
    }

    #[test]
    fn jpeg_lies_on_white_unless_given_a_background() {
        // 8 × 8 blocks of each pixel, so that JPEG's blocks see flat colour.
        let big: Vec<u8> = (0..8).flat_map(|_| RGBA.chunks(4).flat_map(|p| p.repeat(8)).collect::<Vec<_>>()).collect();
        let png = encode::png(&big, 24, 8, image::ExtendedColorType::Rgba8).unwrap();
        for (background, expected) in [(None, [255, 255, 255]), (Some([0, 0, 255]), [0, 0, 255])] {
            let bytes = reencode(&png, background, PictureFormat::Jpeg).unwrap();
            let jpeg = image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg).unwrap().into_rgb8();
            assert_eq!(jpeg.dimensions(), (24, 8));
            let near = |p: [u8; 3], q: [u8; 3]| p.iter().zip(q).all(|(a, b)| a.abs_diff(b) <= 8);
            assert!(near(jpeg.get_pixel(3, 4).0, [255, 0, 0]), "{:?}", jpeg.get_pixel(3, 4));
            assert!(near(jpeg.get_pixel(12, 4).0, expected), "{background:?}: {:?}", jpeg.get_pixel(12, 4));
        }
    }
}
