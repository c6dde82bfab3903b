//! Exception images for `EXCEPTIONS=INIMAGE` and `BLANK`: an image of the
//! requested size that a client can draw in place of the map, carrying the
//! message (PNG) or nothing (transparent PNG, nodata grids).

use super::request::MapFormat;
use crate::cem::Layer;
use crate::encode::{self, Format, Quantization, Samples};
use crate::grid::SampleGrid;
use crate::raster::Raster;
use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};

/// DejaVu Sans Mono (Bitstream Vera licence, `assets/fonts/LICENSE-DejaVu.txt`).
const FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSansMono.ttf");
/// Text height, pixels.
const TEXT_PX: f32 = 14.0;

/// An image of `format` over `grid` with no data in it.
pub fn blank(grid: &SampleGrid, format: MapFormat, heights_16: Quantization) -> Vec<u8> {
    let (w, h) = (grid.width(), grid.height());
    match format {
        MapFormat::Png => rgba_png(&vec![0u8; 4 * w * h], w, h),
        other => {
            let empty = Raster::filled(w, h, f32::NAN);
            let f = match other {
                MapFormat::Bil16 => Format::Bil16,
                MapFormat::Bil32 => Format::Bil32,
                _ => Format::Tiff,
            };
            encode::encode(Layer::Dem, Samples::Float(&empty), grid, f, heights_16).map(|e| e.bytes).unwrap_or_default()
        }
    }
}

/// A transparent RGBA PNG of `w × h` with `message` written on it.
pub fn message(message: &str, w: usize, h: usize) -> Vec<u8> {
    let mut rgba = vec![0u8; 4 * w * h];
    if let Ok(font) = FontRef::try_from_slice(FONT) {
        let scaled = font.as_scaled(PxScale::from(TEXT_PX));
        let advance = scaled.h_advance(font.glyph_id('M')).max(1.0);
        let per_line = ((w as f32 - 8.0) / advance).max(1.0) as usize;
        let chars: Vec<char> = message.chars().collect();
        for (line, text) in chars.chunks(per_line).enumerate() {
            let baseline = 4.0 + scaled.ascent() + line as f32 * scaled.height();
            for (i, &c) in text.iter().enumerate() {
                let glyph = font
                    .glyph_id(c)
                    .with_scale_and_position(PxScale::from(TEXT_PX), point(4.0 + i as f32 * advance, baseline));
                if let Some(outline) = font.outline_glyph(glyph) {
                    let b = outline.px_bounds();
                    outline.draw(|x, y, coverage| {
                        let (px, py) = (b.min.x as i64 + x as i64, b.min.y as i64 + y as i64);
                        if px >= 0 && py >= 0 && (px as usize) < w && (py as usize) < h {
                            let i = 4 * (py as usize * w + px as usize);
                            let a = ((coverage * 255.0) as u8).max(rgba[i + 3]);
                            rgba[i..i + 4].copy_from_slice(&[200, 0, 0, a]);
                        }
                    });
                }
            }
        }
    }
    rgba_png(&rgba, w, h)
}

fn rgba_png(rgba: &[u8], w: usize, h: usize) -> Vec<u8> {
    encode::png(rgba, w, h, image::ExtendedColorType::Rgba8).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_leave_ink_and_blanks_are_empty() {
        let png = message("LayerNotDefined: layer \"x\" is not served", 200, 60);
        let img = image::load_from_memory(&png).unwrap().into_rgba8();
        assert_eq!(img.dimensions(), (200, 60));
        assert!(img.pixels().filter(|p| p.0[3] > 128).count() > 100);
        let grid = crate::grid::BBox::parse("0,0,1,1").unwrap().area_grid(3, 2).unwrap();
        assert_eq!(blank(&grid, MapFormat::Bil16, Quantization::PNG16_HEIGHTS).len(), 3 * 2 * 2);
        let blank_png =
            image::load_from_memory(&blank(&grid, MapFormat::Png, Quantization::PNG16_HEIGHTS)).unwrap().into_rgba8();
        assert!(blank_png.pixels().all(|p| p.0[3] == 0));
    }
}
