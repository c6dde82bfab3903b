//! What WMS pictures (`relief`, `colour`) show where there is no data
//! (WMS 1.3.0 §7.3.3.9): nothing with `TRANSPARENT=TRUE`, else `BGCOLOR`.
//! Pictures are computed and cached transparent; an opaque one is laid on
//! its background as it is answered.

use crate::encode::{self, EncodeError};

/// `pixels` RGBA pixels of `background`, or transparent if none.
pub fn filled(pixels: usize, background: Option<[u8; 3]>) -> Vec<u8> {
    match background {
        Some([r, g, b]) => [r, g, b, 255].repeat(pixels),
        None => vec![0; 4 * pixels],
    }
}

/// The RGBA PNG `png` laid on `background`: an opaque RGB PNG.
pub fn flatten(png: &[u8], background: [u8; 3]) -> Result<Vec<u8>, EncodeError> {
    let picture =
        image::load_from_memory_with_format(png, image::ImageFormat::Png).map_err(|e| EncodeError(e.to_string()))?;
    let rgba = picture.into_rgba8();
    let (w, h) = rgba.dimensions();
    let rgb: Vec<u8> = rgba
        .pixels()
        .flat_map(|p| {
            let [r, g, b, a] = p.0;
            let over = |c: u8, under: u8| {
                ((u16::from(c) * u16::from(a) + u16::from(under) * (255 - u16::from(a)) + 127) / 255) as u8
            };
            [over(r, background[0]), over(g, background[1]), over(b, background[2])]
        })
        .collect();
    encode::png(&rgb, w as usize, h as usize, image::ExtendedColorType::Rgb8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_picture_is_laid_on_its_background() {
        // Opaque red, transparent, and green at half cover.
        let rgba = [255, 0, 0, 255, 9, 9, 9, 0, 0, 255, 0, 128];
        let png = encode::png(&rgba, 3, 1, image::ExtendedColorType::Rgba8).unwrap();
        let flat = image::load_from_memory(&flatten(&png, [0, 0, 255]).unwrap()).unwrap();
        assert_eq!(flat.color(), image::ColorType::Rgb8);
        let px: Vec<[u8; 3]> = flat.into_rgb8().pixels().map(|p| p.0).collect();
        assert_eq!(px, vec![[255, 0, 0], [0, 0, 255], [0, 128, 127]]);
        assert!(flatten(b"not a png", [0, 0, 0]).is_err());
    }
}
