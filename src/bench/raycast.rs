//! `sylva bench raycast`: error against run time of the ray caster's knobs
//! (dissertation Table 6.1 and Figure 6.16). Fixed views of the demo and of
//! rmnp — a low flight and a grazing view to the horizon each — are
//! rendered with the linear march at 30/50/70/90 steps and the exact
//! traversal, each with 10/20/30 shadow steps, plus the exact traversal with
//! the canopy fade (the default) and without sun. Each setting reports GPU
//! time per frame, texture fetches per pixel, and its departure from the
//! exact CPU reference (with 30 shadow steps): pixels missed, depth error,
//! colour PSNR.
//!
//! The canopy fade is off except in its own row, so that every other row
//! measures the traversal and shadows alone against the reference.

use super::table;
use crate::client::camera::Camera;
use crate::client::fly::{self, FlyOptions};
use crate::client::path::CameraPath;
use crate::client::raycast::{Fade, Traversal, TreeBlend};
use crate::client::reference::{self, Image, Lighting};
use crate::client::render::uniforms::FrameSettings;
use crate::client::render::{FrameStats, Readback, Rendered, Renderer};
use crate::client::source::RegionSource;
use crate::client::store::TileStore;
use crate::client::tile::TileData;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// Shadow steps of the reference image.
const REFERENCE_SHADOW_STEPS: u32 = 30;
/// Frames timed per setting at least (the median is reported).
const TIMED_FRAMES: usize = 3;
/// Warm-up: frames are rendered untimed for at least [`WARM_MIN_MS`], then
/// in windows of [`WARM_WINDOW_MS`] (at least one frame each) until a
/// window's median time is within [`SETTLED`] of the one before, or for
/// [`WARM_MAX_MS`]: the first frames upload the tiles and build pipelines,
/// and a GPU left idle while the CPU reference was drawn lowers its clocks
/// (an H200: from 1,980 to 345 MHz within a second of idling) and raises
/// them only after some busy time (about half a second there), steadily
/// slow meanwhile.
const WARM_MIN_MS: f64 = 1000.0;
/// A warm-up window.
const WARM_WINDOW_MS: f64 = 100.0;
/// Relative change between warm-up windows taken as settled.
const SETTLED: f64 = 0.03;
/// Longest warm-up.
const WARM_MAX_MS: f64 = 3000.0;
/// Frames are timed until their wall time reaches this too, so that a fast
/// GPU's median is taken over many frames.
const TIMED_WALL_MS: f64 = 250.0;
/// Frames timed per setting at most.
const MAX_TIMED_FRAMES: usize = 1000;

/// One fixed view: a region, a camera path and the time on it.
#[derive(Clone, Debug)]
pub struct View {
    /// A name for the tables.
    pub name: String,
    /// Region configuration (`None`: the demo).
    pub config: Option<PathBuf>,
    /// Camera path file.
    pub path: PathBuf,
    /// Time on the path, seconds.
    pub t_s: f64,
}

/// One setting's measurements on one view.
#[derive(Clone, Debug)]
pub struct Row {
    /// View name.
    pub view: String,
    /// Setting name, e.g. `linear 30 + 10`.
    pub setting: String,
    /// Median GPU (or, without timestamps, wall) time per frame, ms.
    pub ms: f64,
    /// Median wall time of a frame rendered and waited for, ms: encoding,
    /// submission and the GPU's work, one frame at a time.
    pub wall_ms: f64,
    /// Frames per second with frames in flight, as an interactive loop
    /// renders them (wall time).
    pub fps: f64,
    /// Of the GPU time, with rays in a compute pass: median ms of the rays'
    /// pass and of the depth fill after it.
    pub rays_ms: Option<(f64, f64)>,
    /// Mean and 99th-percentile view-ray fetches per ray-cast pixel.
    pub fetches: (f64, u32),
    /// Mean shadow and shading fetches per ray-cast pixel.
    pub shadow_fetches: f64,
    /// Share of the reference's surface pixels missed, percent.
    pub missed_pct: f64,
    /// RMS relative depth error over pixels both hit.
    pub depth_rms_rel: f64,
    /// Colour PSNR over pixels both hit, dB.
    pub psnr_db: f64,
}

/// A setting: name, traversal, shadow steps, sun on, canopy fade on.
type Setting = (String, Traversal, u32, bool, bool);

/// The settings, in the table's order.
fn settings() -> Vec<Setting> {
    let mut out = Vec::new();
    for steps in [30, 50, 70, 90] {
        for shadows in [10, 20, 30] {
            out.push((format!("linear {steps} + {shadows}"), Traversal::Linear(steps), shadows, true, false));
        }
    }
    for shadows in [10, 20, 30] {
        out.push((format!("exact + {shadows}"), Traversal::Exact, shadows, true, false));
    }
    out.push(("exact + 10, canopy fade".into(), Traversal::Exact, 10, true, true));
    out.push(("exact, no sun".into(), Traversal::Exact, 0, false, false));
    out
}

/// `name` if a setting is so named, else an error listing the names.
pub fn setting_named(name: &str) -> Result<String, String> {
    let all = settings();
    if all.iter().any(|s| s.0 == name) {
        return Ok(name.to_string());
    }
    let names: Vec<&str> = all.iter().map(|s| s.0.as_str()).collect();
    Err(format!("no setting is named {name:?}; the settings: {names:?}"))
}

/// The settings named in `only`, in the table's order (all when empty); an
/// unknown name is an error listing the known ones.
fn chosen(only: &[String]) -> Result<Vec<Setting>, String> {
    for name in only {
        setting_named(name)?;
    }
    Ok(settings().into_iter().filter(|s| only.is_empty() || only.contains(&s.0)).collect())
}

/// The default views: a low flight and a grazing view over each region.
pub fn default_views(rmnp: &Path) -> Vec<View> {
    let paths = |name: &str| PathBuf::from("config/paths").join(name);
    vec![
        View { name: "demo valley".into(), config: None, path: paths("demo_valley.toml"), t_s: 12.0 },
        View { name: "demo horizon".into(), config: None, path: paths("demo_horizon.toml"), t_s: 8.0 },
        View {
            name: "rmnp valley".into(),
            config: Some(rmnp.to_path_buf()),
            path: paths("rmnp_valley.toml"),
            t_s: 10.0,
        },
        View {
            name: "rmnp horizon".into(),
            config: Some(rmnp.to_path_buf()),
            path: paths("rmnp_horizon.toml"),
            t_s: 0.0,
        },
    ]
}

/// Runs every setting named in `only` (all when empty) on every view at `size`.
pub fn run(views: &[View], size: (u32, u32), only: &[String], renderer: &mut Renderer) -> Result<Vec<Row>, String> {
    let settings = chosen(only)?;
    let mut rows = Vec::new();
    for view in views {
        let region = crate::config::load(view.config.as_deref()).map_err(|e| e.to_string())?;
        let source = RegionSource::new(Arc::new(region));
        let path = CameraPath::load(&view.path).map_err(|e| e.to_string())?;
        let camera = camera_at(&path, view.t_s, size);
        let options = FlyOptions::default();
        let mut store = TileStore::new(options.halo, usize::MAX, 2).map_err(|e| e.to_string())?;
        let tiles = fly::visible_tiles(&source, &mut store, None, &camera, &options, renderer.cache_slots())
            .map_err(|e| e.to_string())?
            .tiles;
        let tiles: Vec<TileData> = tiles.iter().map(|t| t.as_ref().clone()).collect();
        let lighting = Lighting { sun_ecef: path.sun_ecef(), shadow_steps: REFERENCE_SHADOW_STEPS, fade: Fade::NONE };
        let truth = reference::render(&camera, &tiles, &lighting);
        for (name, traversal, shadows, sun, fade) in settings.iter().cloned() {
            let fade = if fade { default_fade(&camera) } else { Fade::NONE };
            let frame =
                FrameSettings { traversal, shadow_steps: shadows, sun_ecef: path.sun_ecef().filter(|_| sun), fade };
            let refs: Vec<&TileData> = tiles.iter().collect();
            let Timed { ms, wall_ms, fps, rays_ms } = time_frames(renderer, &camera, &refs, &frame)?;
            let out = renderer.render(&camera, &refs, &frame, Readback::All).map_err(|e| e.to_string())?;
            rows.push(Row { ms, wall_ms, fps, rays_ms, ..row(&view.name, &name, &out, &truth) });
        }
    }
    Ok(rows)
}

/// Median times per frame of one view and setting after the warm-up: GPU
/// (or wall), wall, and the compute rays' pass and depth fill where
/// measured; at least [`TIMED_FRAMES`] frames, more until they have taken
/// [`TIMED_WALL_MS`].
fn time_frames(
    renderer: &mut Renderer,
    camera: &Camera,
    tiles: &[&TileData],
    frame: &FrameSettings,
) -> Result<Timed, String> {
    let mut render =
        || renderer.render(camera, tiles, frame, Readback::None).map(|out| out.stats).map_err(|e| e.to_string());
    warm_up(&mut render)?;
    let mut stats = Vec::new();
    while stats.len() < MAX_TIMED_FRAMES
        && (stats.len() < TIMED_FRAMES || stats.iter().map(|s: &FrameStats| s.wall_ms).sum::<f64>() < TIMED_WALL_MS)
    {
        stats.push(render()?);
    }
    let column = |f: &dyn Fn(&FrameStats) -> Option<f64>| {
        let values: Vec<f64> = stats.iter().filter_map(f).collect();
        (!values.is_empty()).then(|| median(values))
    };
    Ok(Timed {
        fps: throughput(renderer, camera, tiles, frame)?,
        ms: median(stats.iter().map(frame_ms).collect()),
        wall_ms: median(stats.iter().map(|s| s.wall_ms).collect()),
        rays_ms: column(&|s| s.gpu_rays_ms.map(|t| t.0)).zip(column(&|s| s.gpu_rays_ms.map(|t| t.1))),
    })
}

/// Frames per second rendered with frames in flight (submitted without
/// waiting for each, up to [`crate::client::render::FRAMES_IN_FLIGHT`] at
/// once) over at least [`TIMED_WALL_MS`], the last one waited for.
fn throughput(
    renderer: &mut Renderer,
    camera: &Camera,
    tiles: &[&TileData],
    frame: &FrameSettings,
) -> Result<f64, String> {
    renderer.pipelined(true);
    let start = Instant::now();
    let mut frames = 0;
    let rendered = loop {
        if let Err(e) = renderer.render(camera, tiles, frame, Readback::None) {
            break Err(e.to_string());
        }
        frames += 1;
        if frames >= TIMED_FRAMES && start.elapsed().as_secs_f64() * 1e3 >= TIMED_WALL_MS {
            break Ok(());
        }
    };
    renderer.wait();
    renderer.pipelined(false);
    rendered.map(|()| frames as f64 / start.elapsed().as_secs_f64())
}

/// Median times of a setting (see [`Row`]).
struct Timed {
    ms: f64,
    wall_ms: f64,
    fps: f64,
    rays_ms: Option<(f64, f64)>,
}

/// Renders untimed until the frame time settles (see [`WARM_WINDOW_MS`]).
fn warm_up(render: &mut dyn FnMut() -> Result<FrameStats, String>) -> Result<(), String> {
    let start = Instant::now();
    while start.elapsed().as_secs_f64() * 1e3 < WARM_MIN_MS {
        render()?;
    }
    let mut last: Option<f64> = None;
    loop {
        let window = Instant::now();
        let mut times = vec![frame_ms(&render()?)];
        while window.elapsed().as_secs_f64() * 1e3 < WARM_WINDOW_MS {
            times.push(frame_ms(&render()?));
        }
        let now = median(times);
        let settled = last.is_some_and(|last| (now / last - 1.0).abs() <= SETTLED);
        if settled || start.elapsed().as_secs_f64() * 1e3 >= WARM_MAX_MS {
            return Ok(());
        }
        last = Some(now);
    }
}

/// A frame's GPU time, or its wall time without timestamps.
fn frame_ms(stats: &FrameStats) -> f64 {
    stats.gpu_ms.unwrap_or(stats.wall_ms)
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn camera_at(path: &CameraPath, t_s: f64, size: (u32, u32)) -> Camera {
    let k = path.at(t_s);
    Camera::looking(
        crate::client::globe::Geodetic::new(k.lon, k.lat, k.height_m),
        k.heading_deg,
        k.pitch_deg,
        path.fov_deg,
        size,
    )
}

/// The fade `sylva fly` uses.
fn default_fade(camera: &Camera) -> Fade {
    let (canopy_ref_m, lo_px, hi_px) = FlyOptions::default().fade;
    Fade { focal_px: camera.focal_px(), canopy_ref_m, lo_px, hi_px, trees: TreeBlend::NONE }
}

/// One plotted quantity of a benchmark row.
type Metric = dyn Fn(&Row) -> f64;

fn row(view: &str, setting: &str, out: &Rendered, truth: &Image) -> Row {
    let d = reference::compare(&out.colour, &out.view_z_m, truth);
    let mut rays: Vec<[u32; 2]> = out.fetches.iter().copied().filter(|f| f[0] > 0).collect();
    let n = rays.len().max(1) as f64;
    rays.sort_by_key(|f| f[0]);
    let p99 = rays.get(rays.len() * 99 / 100).map_or(0, |f| f[0]);
    let hits = truth.view_z_m.iter().filter(|&&z| z > 0.0).count().max(1);
    Row {
        view: view.into(),
        setting: setting.into(),
        ms: f64::NAN,
        wall_ms: f64::NAN,
        fps: f64::NAN,
        rays_ms: None,
        fetches: (rays.iter().map(|f| f[0] as f64).sum::<f64>() / n, p99),
        shadow_fetches: rays.iter().map(|f| f[1] as f64).sum::<f64>() / n,
        missed_pct: 100.0 * d.misses as f64 / hits as f64,
        depth_rms_rel: d.depth_rms_rel,
        psnr_db: d.psnr_db,
    }
}

/// The table of one run.
pub fn report(rows: &[Row], size: (u32, u32), gpu: &str) -> String {
    let header = [
        "view",
        "setting",
        "GPU ms/frame",
        "wall ms/frame",
        "frames/s in flight",
        "rays + fill ms",
        "fetches mean",
        "fetches p99",
        "shadow fetches",
        "% missed",
        "depth RMS rel",
        "PSNR dB",
    ];
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                r.view.clone(),
                r.setting.clone(),
                format!("{:.3}", r.ms),
                format!("{:.3}", r.wall_ms),
                format!("{:.0}", r.fps),
                r.rays_ms.map_or("–".into(), |(rays, fill)| format!("{rays:.3} + {fill:.3}")),
                format!("{:.1}", r.fetches.0),
                r.fetches.1.to_string(),
                format!("{:.1}", r.shadow_fetches),
                format!("{:.3}", r.missed_pct),
                format!("{:.1e}", r.depth_rms_rel),
                if r.psnr_db.is_finite() { format!("{:.1}", r.psnr_db) } else { "∞".into() },
            ]
        })
        .collect();
    format!(
        "sylva bench raycast — {}×{} on {gpu}; reference: exact CPU ray caster with {REFERENCE_SHADOW_STEPS} shadow steps\n{}",
        size.0,
        size.1,
        table(&header, &cells)
    )
}

/// Error against time: PSNR (top) and pixels missed (bottom) against ms per
/// frame, a marker per view, a colour per traversal.
pub fn plot(rows: &[Row]) -> Result<Vec<u8>, String> {
    use plotters::prelude::*;
    let views: Vec<&str> = rows.iter().map(|r| r.view.as_str()).fold(Vec::new(), |mut v, n| {
        if !v.contains(&n) {
            v.push(n);
        }
        v
    });
    let kinds = ["linear 30", "linear 50", "linear 70", "linear 90", "exact"];
    let colours = [RED, MAGENTA, BLUE, CYAN, BLACK];
    let timed: Vec<&Row> = rows
        .iter()
        .filter(|r| r.setting.starts_with("linear") || r.setting.starts_with("exact +"))
        .filter(|r| !r.setting.contains("fade"))
        .collect();
    let ms_max = timed.iter().map(|r| r.ms).fold(1.0, f64::max) * 1.1;
    let psnr = |r: &Row| if r.psnr_db.is_finite() { r.psnr_db.min(90.0) } else { 90.0 };
    super::plot::png((1000, 900), |root| {
        let panels = root.split_evenly((2, 1));
        // Legends clear of the points: the time axis starts at 0, far left of
        // any frame's time; PSNR lies high, misses low.
        let metrics: [(&str, f64, &Metric, SeriesLabelPosition); 2] = [
            (
                "colour PSNR against the exact reference, dB (∞ drawn at 90)",
                95.0,
                &psnr,
                SeriesLabelPosition::LowerLeft,
            ),
            ("pixels missed, %", 0.6, &|r: &Row| r.missed_pct, SeriesLabelPosition::UpperLeft),
        ];
        for (area, (caption, top, metric, corner)) in panels.iter().zip(metrics) {
            let top = timed.iter().map(|r| metric(r)).fold(top, f64::max);
            let mut chart = ChartBuilder::on(area)
                .caption(caption, ("sans-serif", 18))
                .margin(12)
                .x_label_area_size(36)
                .y_label_area_size(56)
                .build_cartesian_2d(0.0..ms_max, 0.0..top)
                .map_err(|e| e.to_string())?;
            chart.configure_mesh().x_desc("GPU ms per frame").draw().map_err(|e| e.to_string())?;
            for (kind, colour) in kinds.iter().zip(colours) {
                let points: Vec<(f64, f64, usize)> = timed
                    .iter()
                    .filter(|r| r.setting.starts_with(kind))
                    .map(|r| (r.ms, metric(r), views.iter().position(|v| *v == r.view).unwrap_or(0)))
                    .collect();
                if points.is_empty() {
                    continue;
                }
                chart
                    .draw_series(points.iter().map(|&(x, y, view)| marker((x, y), view, colour)))
                    .map_err(|e| e.to_string())?
                    .label(*kind)
                    .legend(move |(x, y)| Circle::new((x, y), 4, colour.filled()));
            }
            for (k, view) in views.iter().enumerate() {
                chart
                    .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
                    .map_err(|e| e.to_string())?
                    .label(*view)
                    .legend(move |at| marker(at, k, BLACK));
            }
            super::plot::legend(&mut chart, corner)?;
        }
        Ok(())
    })
}

/// A marker per view: disc, cross, triangle, ring.
fn marker<DB: plotters::prelude::DrawingBackend, C: Clone + 'static>(
    at: C,
    view: usize,
    colour: plotters::style::RGBColor,
) -> plotters::element::DynElement<'static, DB, C> {
    use plotters::prelude::*;
    match view % 4 {
        0 => Circle::new(at, 4, colour.filled()).into_dyn(),
        1 => Cross::new(at, 5, colour.stroke_width(2)).into_dyn(),
        2 => TriangleMarker::new(at, 5, colour.filled()).into_dyn(),
        _ => Circle::new(at, 5, colour.stroke_width(2)).into_dyn(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_picks_the_named_settings_in_table_order_and_names_an_unknown_one() {
        let names = |only: &[&str]| {
            let only: Vec<String> = only.iter().map(|s| s.to_string()).collect();
            chosen(&only).map(|c| c.into_iter().map(|s| s.0).collect::<Vec<_>>())
        };
        assert_eq!(names(&[]).map(|n| n.len()), Ok(settings().len()));
        assert_eq!(names(&["exact + 10", "linear 30 + 10"]), Ok(vec!["linear 30 + 10".into(), "exact + 10".into()]));
        let err = names(&["exact + 10", "exact + 11"]).unwrap_err();
        assert!(err.contains("\"exact + 11\"") && err.contains("linear 90 + 30"), "{err}");
    }
}
