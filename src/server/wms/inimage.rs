//! Exception images for `EXCEPTIONS=INIMAGE` and `BLANK`: an image of the
//! requested size that a client can draw in place of the map, carrying the
//! message (PNG) or nothing (transparent PNG, nodata grids); and the empty
//! map answered where a request has no data.

use super::picture::{self, PictureFormat};
use super::request::{MapFormat, MapLayer};
use super::text::{Canvas, Pen};
use crate::cem::Layer;
use crate::encode::{self, Quantization, Samples};
use crate::grid::SampleGrid;
use crate::raster::Raster;

/// An image of `format` over `grid` with no data in it: a data layer's
/// nodata samples in its own encoding, or a picture of `background`
/// (transparent if none).
pub fn blank(
    grid: &SampleGrid,
    layer: MapLayer,
    format: MapFormat,
    heights_16: Quantization,
    background: Option<[u8; 3]>,
) -> Vec<u8> {
    let (w, h) = (grid.width(), grid.height());
    // A data layer in JPEG is a picture of it ([`crate::encode::data_picture`]).
    let (MapLayer::Data(layer), Some(f)) = (layer, format.data()) else {
        let picture = format.picture().unwrap_or(PictureFormat::Png);
        return picture::encode(&picture::filled(w * h, background), w, h, background, picture).unwrap_or_default();
    };
    let encoded = match layer {
        Layer::Surface => {
            let none = Raster::filled(w, h, crate::cem::surface::NODATA);
            encode::encode(layer, Samples::Class(&none), grid, f, heights_16)
        }
        _ => encode::encode(layer, Samples::Float(&Raster::filled(w, h, f32::NAN)), grid, f, heights_16),
    };
    encoded.map(|e| e.bytes).unwrap_or_default()
}

/// `text` in lines of at most `width` characters, broken at spaces where a
/// word fits on a line, within a longer word where it does not.
fn wrapped(text: &str, width: usize) -> Vec<Vec<char>> {
    let mut lines: Vec<Vec<char>> = Vec::new();
    let mut line: Vec<char> = Vec::new();
    for word in text.split(' ').filter(|w| !w.is_empty()) {
        let word: Vec<char> = word.chars().collect();
        if !line.is_empty() && line.len() + 1 + word.len() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.extend(word);
        while line.len() > width {
            let rest = line.split_off(width);
            lines.push(std::mem::replace(&mut line, rest));
        }
    }
    lines.push(line);
    lines
}

/// A picture of `w × h` of `background` (transparent if none and PNG) with
/// `message` written on it in dark red.
pub fn message(message: &str, w: usize, h: usize, background: Option<[u8; 3]>, format: PictureFormat) -> Vec<u8> {
    const RED: [u8; 3] = [200, 0, 0];
    let mut rgba = picture::filled(w * h, background);
    if let Some(pen) = Pen::new() {
        let mut canvas = Canvas { rgba: &mut rgba, width: w, opaque: background.is_some() };
        let per_line = ((w as f32 - 8.0) / pen.advance()).max(1.0) as usize;
        for (line, text) in wrapped(message, per_line).iter().enumerate() {
            let baseline = 4.0 + pen.ascent() + line as f32 * pen.line_height();
            pen.write(&mut canvas, &String::from_iter(text), (4.0, baseline), RED);
        }
    }
    picture::encode(&rgba, w, h, background, format).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_leave_ink_and_blanks_are_empty() {
        let png = message("LayerNotDefined: layer \"x\" is not served", 200, 60, None, PictureFormat::Png);
        let img = image::load_from_memory(&png).unwrap().into_rgba8();
        assert_eq!(img.dimensions(), (200, 60));
        assert!(img.pixels().filter(|p| p.0[3] > 128).count() > 100);
        let on_white = message("LayerNotDefined", 200, 60, Some([255, 255, 255]), PictureFormat::Png);
        let img = image::load_from_memory(&on_white).unwrap().into_rgba8();
        assert!(img.pixels().all(|p| p.0[3] == 255), "opaque on its background");
        assert!(img.pixels().filter(|p| p.0[1] < 128).count() > 50, "with red ink");
    }

    #[test]
    fn messages_break_between_words() {
        let text = |lines: Vec<Vec<char>>| lines.into_iter().map(String::from_iter).collect::<Vec<_>>();
        assert_eq!(text(wrapped("InvalidFormat: dem is served", 16)), ["InvalidFormat:", "dem is served"]);
        assert_eq!(text(wrapped("abcdefghij kl", 4)), ["abcd", "efgh", "ij", "kl"]);
        assert_eq!(text(wrapped("", 4)), [""]);
    }

    #[test]
    fn blanks_are_nodata_in_the_layers_encoding_or_the_background() {
        let grid = crate::grid::BBox::parse("0,0,1,1").unwrap().area_grid(3, 2).unwrap();
        let q = Quantization::PNG16_HEIGHTS;
        let dem = MapLayer::Data(Layer::Dem);
        assert_eq!(blank(&grid, dem, MapFormat::Bil16, q, None), [0x00, 0x80].repeat(6), "-32768 everywhere");
        let heights = image::load_from_memory(&blank(&grid, dem, MapFormat::Png, q, None)).unwrap();
        assert_eq!(heights.color(), image::ColorType::L16, "a data layer stays 16-bit grey");
        assert!(heights.into_luma16().pixels().all(|p| p.0[0] == 0), "code 0 is nodata");
        let see_through = image::load_from_memory(&blank(&grid, MapLayer::Relief, MapFormat::Png, q, None)).unwrap();
        assert!(see_through.into_rgba8().pixels().all(|p| p.0[3] == 0));
        let white = blank(&grid, MapLayer::Relief, MapFormat::Png, q, Some([255, 250, 240]));
        assert!(image::load_from_memory(&white).unwrap().into_rgba8().pixels().all(|p| p.0 == [255, 250, 240, 255]));
        let jpeg = blank(&grid, MapLayer::Colour, MapFormat::Jpeg, q, None);
        let jpeg = image::load_from_memory_with_format(&jpeg, image::ImageFormat::Jpeg).unwrap().into_rgb8();
        assert!(jpeg.pixels().all(|p| p.0.iter().all(|&c| c >= 250)), "JPEG has no alpha: white");
    }
}
