//! Plots of `sylva bench lod`: selection time per frame with and without
//! splitting and deferral (000 Figure 3), tiles evaluated per frame by
//! full and deferred refinement (004 Figure 3), and a flight's predicted
//! and measured frame time against its budget (000 Figure 2), all on log
//! scales.

use super::lod::Frame;
use super::lod_frames::FrameTime;
use super::plot::{self, Area};
use plotters::prelude::*;

const SIZE: (u32, u32) = (1000, 800);

/// Draws the two panels for `frames` and returns the PNG.
pub fn png(title: &str, frames: &[Frame]) -> Result<Vec<u8>, String> {
    plot::png(SIZE, |root| {
        let (top, bottom) = root.split_vertically(SIZE.1 / 2);
        let times: &Series<'_, Frame> = &[
            ("unsplit", RED, |f| f.ms_unsplit),
            ("split", BLUE, |f| f.ms_split),
            ("split + deferral", GREEN, |f| f.ms_deferred),
        ];
        panel(&top, &format!("{title}: LOD selection time"), "ms", frames, times)?;
        let work: &Series<'_, Frame> = &[
            ("full refinement", RED, |f| f.touched_full as f64),
            ("deferred", BLUE, |f| f.touched_deferred.max(1) as f64),
        ];
        panel(&bottom, "tiles evaluated per frame", "tiles", frames, work)
    })
}

/// Draws a flight's frame times against its budget and returns the PNG.
pub fn frame_times_png(title: &str, frames: &[FrameTime]) -> Result<Vec<u8>, String> {
    plot::png((SIZE.0, SIZE.1 / 2), |root| {
        let times: &Series<'_, FrameTime> = &[
            ("budget", BLACK, |f| f.budget_ms),
            ("predicted", BLUE, |f| f.predicted_ms),
            ("measured", RED, |f| f.measured_ms),
        ];
        panel(root, &format!("{title}: frame time under a budget"), "ms", frames, times)
    })
}

type Series<'a, T> = [(&'a str, RGBColor, fn(&T) -> f64)];

/// One log-scale panel of per-frame series.
fn panel<T>(area: &Area<'_>, caption: &str, unit: &str, frames: &[T], series: &Series<'_, T>) -> Result<(), String> {
    let values = frames.iter().flat_map(|f| series.iter().map(move |s| (s.2)(f)));
    let (lo, hi) = values.filter(|v| *v > 0.0).fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
    let (lo, hi) = if lo <= hi { (lo / 1.5, hi * 1.5) } else { (0.001, 1.0) };
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(0..frames.len(), (lo..hi).log_scale())
        .map_err(|e| e.to_string())?;
    chart.configure_mesh().x_desc("frame").y_desc(unit).draw().map_err(|e| e.to_string())?;
    for &(name, color, value) in series {
        let points = frames.iter().enumerate().map(|(i, f)| (i, value(f).max(lo)));
        chart
            .draw_series(LineSeries::new(points, color))
            .map_err(|e| e.to_string())?
            .label(name)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], color));
    }
    plot::legend(&mut chart, SeriesLabelPosition::UpperRight)
}
