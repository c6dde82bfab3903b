//! WMS GetLegendGraphic (the Styled Layer Descriptor profile's request, which
//! QGIS asks for to draw a layer's legend; the capabilities name its URL in
//! each layer's `LegendURL`): a picture of what a layer's colours mean —
//! a swatch per surface class, grey ramps of cover and canopy height with
//! their values, the shades of the height layers — under the layer's title.
//!
//! The swatches are the colours the layer's pictures use
//! ([`crate::encode::relief`], [`crate::encode::data_picture`]); a region
//! with a map draws its pictures in the map's colours, which the legend
//! says, keeping the class swatches for where the map has none.

use super::super::exception::{Code, Exception};
use super::capabilities::title;
use super::picture::{self, PictureFormat};
use super::request::{self, MapLayer, Params};
use super::text::{Canvas, Pen};
use crate::cem::Layer;
use crate::cem::surface::SurfaceType;
use crate::encode::data_picture::{CANOPY_WHITE_M, value_grey};
use crate::encode::relief::{LEVEL_SHADE, class_colour, lit};

/// Swatch size when WIDTH and HEIGHT are not given, pixels (GeoServer's).
pub const SWATCH_PX: usize = 20;
/// Largest swatch side, pixels.
const MAX_SWATCH_PX: usize = 256;
/// Space around the legend and between a swatch and its label, pixels.
const PAD: usize = 4;
/// Ink of the text.
const INK: [u8; 3] = [0, 0, 0];

/// A checked GetLegendGraphic request.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LegendRequest {
    /// The layer whose legend is drawn.
    pub layer: MapLayer,
    /// PNG or JPEG.
    pub format: PictureFormat,
    /// Each swatch's width and height, pixels.
    pub swatch: (usize, usize),
    /// What the legend is drawn on (`BGCOLOR`, white), or nothing
    /// (`TRANSPARENT=TRUE`, PNG only).
    pub background: Option<[u8; 3]>,
}

/// Parses a GetLegendGraphic's parameters: `LAYER` (the SLD profile's
/// name; `LAYERS` with one layer is taken too), `FORMAT` (`image/png`
/// when left out), `STYLE` (the default), `WIDTH`/`HEIGHT` of a swatch,
/// `TRANSPARENT` and `BGCOLOR` as in GetMap. `SLD_VERSION`, `SCALE` and
/// `RULE` change nothing here.
pub(super) fn parse(params: &Params) -> Result<LegendRequest, Exception> {
    let name = params
        .get("LAYER")
        .or(params.get("LAYERS"))
        .map(str::trim)
        .filter(|n| !n.is_empty())
        .ok_or_else(|| Exception::new(Code::MissingParameterValue, "LAYER is missing").locator("LAYER"))?;
    let layer = MapLayer::parse(name).ok_or_else(|| {
        Exception::new(Code::LayerNotDefined, format!("layer {name:?} is not served")).locator("LAYER")
    })?;
    let format = match params.get("FORMAT").map(str::trim) {
        None | Some("") => PictureFormat::Png,
        Some(text) => picture_format(text).ok_or_else(|| {
            Exception::new(Code::InvalidFormat, format!("FORMAT={text}: legends are image/png or image/jpeg"))
                .locator("FORMAT")
        })?,
    };
    request::check_styles(params.get("STYLE"), "STYLE")?;
    let swatch = (side(params, "WIDTH")?, side(params, "HEIGHT")?);
    let map_format = match format {
        PictureFormat::Png => request::MapFormat::Png,
        PictureFormat::Jpeg => request::MapFormat::Jpeg,
    };
    let background = request::background(params, Some(map_format))?;
    Ok(LegendRequest { layer, format, swatch, background })
}

/// A picture format named by its MIME type (or short name).
fn picture_format(text: &str) -> Option<PictureFormat> {
    let lower = text.to_ascii_lowercase();
    PictureFormat::of_extension(lower.strip_prefix("image/").unwrap_or(&lower))
}

/// A swatch side: `key`'s whole number of pixels, or the default.
fn side(params: &Params, key: &'static str) -> Result<usize, Exception> {
    let Some(text) = params.get(key).map(str::trim).filter(|t| !t.is_empty()) else { return Ok(SWATCH_PX) };
    text.parse::<usize>().ok().filter(|n| (1..=MAX_SWATCH_PX).contains(n)).ok_or_else(|| {
        let why = format!("{key}={text}: a swatch is 1 to {MAX_SWATCH_PX} pixels");
        Exception::new(Code::InvalidParameterValue, why).locator(key)
    })
}

/// One line of a legend.
#[derive(Clone, Debug, PartialEq)]
enum Entry {
    /// A swatch of this colour and its label.
    Swatch([u8; 3], String),
    /// Text alone.
    Note(String),
}

/// The entries of `layer`'s legend; `map` whether the region's pictures
/// take a map's colours.
fn entries(layer: MapLayer, map: bool) -> Vec<Entry> {
    let grey = |level: f32| [(255.0 * level.clamp(0.0, 1.0)).round() as u8; 3];
    let mut lines = Vec::new();
    match layer {
        MapLayer::Relief | MapLayer::Colour => {
            if layer == MapLayer::Relief {
                lines.push(Entry::Note("hill-shaded, light from the north-west".into()));
            }
            if map {
                lines.push(Entry::Note("the map's colours; where it has none:".into()));
            }
            let shaded = layer == MapLayer::Relief;
            lines.extend(classes(|class, c| if shaded { lit(class, c, LEVEL_SHADE) } else { c.map(|v| v as u8) }));
        }
        MapLayer::Data(Layer::Surface) => lines.extend(classes(|_, c| c.map(|v| v as u8))),
        MapLayer::Data(ramp @ (Layer::Cover | Layer::Canopy)) => {
            let levels = steps(ramp).into_iter().filter_map(|(v, label)| Some((value_grey(ramp, v)?, label)));
            lines.extend(levels.map(|(level, label)| Entry::Swatch(grey(level), label)));
        }
        MapLayer::Data(_) => {
            lines.push(Entry::Note("hill-shaded heights:".into()));
            lines.push(Entry::Swatch(grey(1.0), "slope facing the light (NW)".into()));
            lines.push(Entry::Swatch(grey(LEVEL_SHADE), "level ground".into()));
            lines.push(Entry::Swatch(grey(0.25), "slope facing away".into()));
            lines.push(Entry::Note("values: a data format (bil, tiff)".into()));
        }
    }
    lines
}

/// The values a continuous layer's legend shows, with their labels.
fn steps(layer: Layer) -> Vec<(f32, String)> {
    match layer {
        Layer::Cover => [0.0, 0.25, 0.5, 0.75, 1.0].map(|v| (v, format!("{v} cover"))).into(),
        Layer::Canopy => [0.0, 10.0, 20.0, CANOPY_WHITE_M]
            .map(|m| (m, if m >= CANOPY_WHITE_M { format!("{m} m and taller") } else { format!("{m} m") }))
            .into(),
        _ => Vec::new(),
    }
}

/// A swatch per surface class, in `colour` of the class and its class
/// colour.
fn classes(colour: impl Fn(u8, [f32; 3]) -> [u8; 3]) -> Vec<Entry> {
    SurfaceType::ALL
        .iter()
        .map(|&s| Entry::Swatch(colour(s as u8, class_colour(s as u8)), s.name().to_string()))
        .collect()
}

/// Where a legend's lines go: each line's top and height, and the
/// picture's size.
struct Layout {
    rows: Vec<(usize, usize)>,
    size: (usize, usize),
}

/// Lays out the title and `lines` with swatches of `swatch`.
fn layout(pen: &Pen, heading: &str, lines: &[Entry], (sw, sh): (usize, usize)) -> Layout {
    let text_h = pen.line_height().ceil() as usize;
    let text_w = |t: &str| pen.width(t).ceil() as usize;
    let mut width = text_w(heading);
    let mut rows = Vec::with_capacity(lines.len());
    let mut top = PAD + text_h + PAD;
    for line in lines {
        let (w, h) = match line {
            Entry::Swatch(_, label) => (sw + PAD + text_w(label), sh.max(text_h)),
            Entry::Note(text) => (text_w(text), text_h),
        };
        width = width.max(w);
        rows.push((top, h));
        top += h + PAD / 2;
    }
    Layout { rows, size: (PAD + width + PAD, top + PAD) }
}

/// The legend's picture size for `layer` (the capabilities' `LegendURL`
/// states it).
pub fn size(layer: MapLayer, map: bool, swatch: (usize, usize)) -> (usize, usize) {
    Pen::new().map_or((1, 1), |pen| layout(&pen, title(layer), &entries(layer, map), swatch).size)
}

/// The legend `request` asks for, encoded; `map` whether the region's
/// pictures take a map's colours.
pub fn draw(request: &LegendRequest, map: bool) -> Result<Vec<u8>, crate::encode::EncodeError> {
    let pen = Pen::new().ok_or_else(|| crate::encode::EncodeError("the embedded font does not load".into()))?;
    let (heading, lines) = (title(request.layer), entries(request.layer, map));
    let plan = layout(&pen, heading, &lines, request.swatch);
    let (w, h) = plan.size;
    let mut rgba = picture::filled(w * h, request.background);
    let mut canvas = Canvas { rgba: &mut rgba, width: w, opaque: request.background.is_some() };
    let text_h = pen.line_height();
    let baseline = |top: usize, height: usize| top as f32 + (height as f32 - text_h) / 2.0 + pen.ascent();
    pen.write(&mut canvas, heading, (PAD as f32, baseline(PAD, text_h.ceil() as usize)), INK);
    for (line, &(top, height)) in lines.iter().zip(&plan.rows) {
        let x = match line {
            Entry::Swatch(colour, _) => {
                let (sw, sh) = request.swatch;
                fill_swatch(&mut canvas, (PAD, top + (height - sh) / 2), (sw, sh), *colour);
                PAD + sw + PAD
            }
            Entry::Note(_) => PAD,
        };
        let (Entry::Swatch(_, text) | Entry::Note(text)) = line;
        pen.write(&mut canvas, text, (x as f32, baseline(top, height)), INK);
    }
    picture::encode(&rgba, w, h, request.background, request.format)
}

/// A `size` swatch of `colour` at `corner`, framed in grey so that white
/// and background-coloured swatches show.
fn fill_swatch(canvas: &mut Canvas, corner: (usize, usize), (w, h): (usize, usize), colour: [u8; 3]) {
    const FRAME: [u8; 3] = [128, 128, 128];
    for y in 0..h {
        for x in 0..w {
            let edge = x == 0 || y == 0 || x + 1 == w || y + 1 == h;
            let [r, g, b] = if edge && w > 2 && h > 2 { FRAME } else { colour };
            let k = 4 * ((corner.1 + y) * canvas.width + corner.0 + x);
            canvas.rgba[k..k + 4].copy_from_slice(&[r, g, b, 255]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cem::LayerSamples;
    use crate::encode::data_picture;
    use crate::raster::Raster;

    fn parsed(query: &str) -> Result<LegendRequest, Code> {
        parse(&Params::new(query)).map_err(|e| e.code)
    }

    fn decode(bytes: &[u8]) -> image::RgbaImage {
        image::load_from_memory(bytes).expect("a picture").into_rgba8()
    }

    /// The legend's pixels of exactly `rgb` (a swatch's inside).
    fn count(img: &image::RgbaImage, rgb: [u8; 3]) -> usize {
        img.pixels().filter(|p| p.0 == [rgb[0], rgb[1], rgb[2], 255]).count()
    }

    #[test]
    fn a_request_names_a_served_layer_and_a_picture_format() {
        let legend = parsed("REQUEST=GetLegendGraphic&LAYER=relief").unwrap();
        assert_eq!(legend.layer, MapLayer::Relief);
        assert_eq!((legend.format, legend.swatch, legend.background), (PictureFormat::Png, (20, 20), Some([255; 3])));
        let legend = parsed("LAYERS=canopy&FORMAT=image/jpeg&WIDTH=12&HEIGHT=8&STYLE=default&SLD_VERSION=1.1.0");
        assert_eq!(legend.map(|l| (l.format, l.swatch)), Ok((PictureFormat::Jpeg, (12, 8))));
        assert_eq!(parsed("LAYER=dem&TRANSPARENT=TRUE").unwrap().background, None);
        for (query, code) in [
            ("FORMAT=image/png", Code::MissingParameterValue),
            ("LAYER=", Code::MissingParameterValue),
            ("LAYER=forest", Code::LayerNotDefined),
            ("LAYER=dem&FORMAT=image/tiff", Code::InvalidFormat),
            ("LAYER=dem&FORMAT=application/bil32", Code::InvalidFormat),
            ("LAYER=dem&STYLE=fancy", Code::StyleNotDefined),
            ("LAYER=dem&WIDTH=0", Code::InvalidParameterValue),
            ("LAYER=dem&HEIGHT=257", Code::InvalidParameterValue),
            ("LAYER=dem&WIDTH=2.5", Code::InvalidParameterValue),
            ("LAYER=dem&BGCOLOR=white", Code::InvalidParameterValue),
        ] {
            assert_eq!(parsed(query), Err(code), "{query}");
        }
    }

    fn legend(layer: MapLayer, map: bool) -> image::RgbaImage {
        let request = LegendRequest { layer, format: PictureFormat::Png, swatch: (20, 20), background: Some([255; 3]) };
        let img = decode(&draw(&request, map).unwrap());
        let (w, h) = size(layer, map, (20, 20));
        assert_eq!((img.width() as usize, img.height() as usize), (w, h), "the size the capabilities state");
        assert!(img.pixels().filter(|p| p.0[0] < 64 && p.0[1] < 64 && p.0[2] < 64).count() > 100, "text");
        img
    }

    #[test]
    fn class_swatches_are_the_colours_the_pictures_draw_each_class_in() {
        // The surface layer's picture, a sample of each class.
        let classes = Raster::from_fn(8, 3, |x, _| x.saturating_sub(1).min(5) as u8);
        let picture =
            decode(&data_picture::encode(Layer::Surface, &LayerSamples::Class(classes), &[(1.0, 1.0)]).unwrap());
        let img = legend(MapLayer::Data(Layer::Surface), false);
        for x in 0..6 {
            let [r, g, b, _] = picture.get_pixel(x, 0).0;
            assert_eq!(count(&img, [r, g, b]), 18 * 18, "class {x}: one swatch of its colour");
        }
        // The colour layer draws the classes unshaded, the relief lit as level ground.
        let colour = legend(MapLayer::Colour, false);
        let relief = legend(MapLayer::Relief, true);
        for class in SurfaceType::ALL.map(|s| s as u8) {
            assert!(count(&colour, class_colour(class).map(|v| v as u8)) >= 18 * 18, "{class}");
            assert!(count(&relief, lit(class, class_colour(class), LEVEL_SHADE)) >= 18 * 18, "{class}");
        }
    }

    #[test]
    fn ramps_are_the_greys_the_pictures_draw_their_values_in() {
        for (layer, values) in
            [(Layer::Cover, [0.0, 0.25, 0.5, 0.75, 1.0]), (Layer::Canopy, [0.0, 10.0, 20.0, 30.0, 45.0])]
        {
            let samples = Raster::from_fn(7, 3, |x, _| values[x.saturating_sub(1).min(4)]);
            let picture = decode(&data_picture::encode(layer, &LayerSamples::Float(samples), &[(1.0, 1.0)]).unwrap());
            let img = legend(MapLayer::Data(layer), false);
            for x in 0..5 {
                let [r, g, b, _] = picture.get_pixel(x, 0).0;
                assert!(count(&img, [r, g, b]) >= 18 * 18, "{layer:?} {}: a swatch of its grey", values[x as usize]);
            }
        }
    }

    #[test]
    fn a_transparent_legend_is_clear_around_its_ink_and_jpeg_is_opaque() {
        let mut request = LegendRequest {
            layer: MapLayer::Data(Layer::Cem),
            format: PictureFormat::Png,
            swatch: (1, 40),
            background: None,
        };
        let img = decode(&draw(&request, false).unwrap());
        assert_eq!(img.get_pixel(0, 0).0[3], 0, "transparent corner");
        assert!(img.pixels().any(|p| p.0[3] == 255), "ink and swatches");
        request.format = PictureFormat::Jpeg;
        let jpeg = draw(&request, false).unwrap();
        assert_eq!(image::guess_format(&jpeg).unwrap(), image::ImageFormat::Jpeg);
        assert!(decode(&jpeg).pixels().all(|p| p.0[3] == 255));
    }
}
