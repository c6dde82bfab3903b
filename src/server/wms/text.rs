//! Text written into RGBA pixels with the embedded monospaced font: the
//! messages of exception images and the labels of legends.

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};

/// DejaVu Sans Mono (Bitstream Vera licence, `assets/fonts/LICENSE-DejaVu.txt`).
const FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSansMono.ttf");
/// Text height, pixels.
const TEXT_PX: f32 = 14.0;

/// RGBA pixels to write on: opaque (ink is blended into them) or
/// transparent (ink becomes their alpha).
pub struct Canvas<'a> {
    /// `width × height` RGBA pixels, row by row.
    pub rgba: &'a mut [u8],
    /// Pixels per row.
    pub width: usize,
    /// Whether the pixels are opaque.
    pub opaque: bool,
}

/// The font at the text size, with its metrics.
pub struct Pen {
    font: FontRef<'static>,
}

impl Pen {
    /// The embedded font (`None` only if the font would not load).
    pub fn new() -> Option<Pen> {
        FontRef::try_from_slice(FONT).ok().map(|font| Pen { font })
    }

    fn scaled(&self) -> ab_glyph::PxScaleFont<&FontRef<'static>> {
        self.font.as_scaled(PxScale::from(TEXT_PX))
    }

    /// Width of a character (the font is monospaced), pixels.
    pub fn advance(&self) -> f32 {
        self.scaled().h_advance(self.font.glyph_id('M')).max(1.0)
    }

    /// Height above the baseline, pixels.
    pub fn ascent(&self) -> f32 {
        self.scaled().ascent()
    }

    /// Distance between baselines, pixels.
    pub fn line_height(&self) -> f32 {
        self.scaled().height()
    }

    /// Width of `text`, pixels.
    pub fn width(&self, text: &str) -> f32 {
        text.chars().count() as f32 * self.advance()
    }

    /// Writes `text` in `ink` from `x` on the baseline `baseline`; what
    /// falls outside the canvas is left out.
    pub fn write(&self, canvas: &mut Canvas, text: &str, (x, baseline): (f32, f32), ink: [u8; 3]) {
        let height = canvas.rgba.len() / 4 / canvas.width.max(1);
        for (i, c) in text.chars().enumerate() {
            let position = point(x + i as f32 * self.advance(), baseline);
            let glyph = self.font.glyph_id(c).with_scale_and_position(PxScale::from(TEXT_PX), position);
            let Some(outline) = self.font.outline_glyph(glyph) else { continue };
            let b = outline.px_bounds();
            outline.draw(|gx, gy, coverage| {
                let (px, py) = (b.min.x as i64 + i64::from(gx), b.min.y as i64 + i64::from(gy));
                if px >= 0 && py >= 0 && (px as usize) < canvas.width && (py as usize) < height {
                    let k = 4 * (py as usize * canvas.width + px as usize);
                    blend(&mut canvas.rgba[k..k + 4], ink, coverage, canvas.opaque);
                }
            });
        }
    }
}

/// `ink` of `coverage` on one RGBA pixel: blended into an opaque pixel, as
/// alpha on a transparent one.
fn blend(pixel: &mut [u8], ink: [u8; 3], coverage: f32, opaque: bool) {
    let c = coverage.clamp(0.0, 1.0);
    if opaque {
        for k in 0..3 {
            pixel[k] = (f32::from(pixel[k]) * (1.0 - c) + f32::from(ink[k]) * c).round() as u8;
        }
    } else {
        let a = ((c * 255.0) as u8).max(pixel[3]);
        pixel.copy_from_slice(&[ink[0], ink[1], ink[2], a]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_inks_only_within_its_line_and_the_canvas() {
        let pen = Pen::new().unwrap();
        let (w, h) = (60, 30);
        let mut rgba = vec![255; 4 * w * h];
        let mut canvas = Canvas { rgba: &mut rgba, width: w, opaque: true };
        // Runs off the right edge: clipped, not a panic.
        pen.write(&mut canvas, "legend text", (2.0, 2.0 + pen.ascent()), [0, 0, 0]);
        let dark: Vec<(usize, usize)> = (0..w * h).filter(|&k| rgba[4 * k] < 128).map(|k| (k % w, k / w)).collect();
        assert!(dark.len() > 30, "ink on the canvas");
        let below = (2.0 + pen.line_height()).ceil() as usize;
        assert!(dark.iter().all(|&(_, y)| y < below), "ink within the line");
        assert!(rgba.chunks(4).all(|p| p[3] == 255), "an opaque canvas stays opaque");
        assert_eq!(pen.width("abcd"), 4.0 * pen.advance());
    }
}
