//! Plot canvases for the benchmarks: plotters drawing into an RGB buffer
//! with the bundled font, written with the crate's one PNG writer.

use plotters::prelude::*;

/// The font every label uses (registered once under "sans-serif").
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSansMono.ttf");

/// A drawing area of a bitmap.
pub type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// A white `size` canvas that `draw` fills, as a PNG.
pub fn png(size: (u32, u32), draw: impl FnOnce(&Area<'_>) -> Result<(), String>) -> Result<Vec<u8>, String> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).map_err(|_| "bad font".to_string())?;
    let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        draw(&root)?;
        root.present().map_err(|e| e.to_string())?;
    }
    crate::encode::png(&buf, size.0 as usize, size.1 as usize, image::ExtendedColorType::Rgb8)
        .map_err(|e| e.to_string())
}

/// Draws the legend of `chart`'s labelled series at `at`, boxed on a light
/// ground.
pub fn legend<'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, CT>,
    at: SeriesLabelPosition,
) -> Result<(), String> {
    chart
        .configure_series_labels()
        .position(at)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| e.to_string())
}
