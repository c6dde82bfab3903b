//! `sylva bench sse`: the client's screen-space error selection along the
//! recorded flyovers (`config/paths/*.toml`), deferred (004's distance
//! deferral table, [`crate::client::sse`]) against full re-evaluation every
//! frame: nodes touched and refinement tests per frame, and the check that
//! both select the same tiles in every frame. No GPU: path, camera and tile
//! tree only, as `sylva fly --lod sse` selects before it loads and draws.

use super::table;
use crate::client::camera::Camera;
use crate::client::path::CameraPath;
use crate::client::quadtree::LodRule;
use crate::client::quadtree::Selection;
use crate::client::source::RegionSource;
use crate::client::sse::SseSelector;
use crate::client::tiletree::TileTree;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// One frame of both selectors.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameCounts {
    /// Tiles selected (by both).
    pub tiles: usize,
    /// Refinement tests, deferred and full.
    pub evaluated: (usize, usize),
    /// Nodes touched (refinement and visibility tests), deferred and full.
    pub touched: (usize, usize),
    /// Selection ms, deferred and full.
    pub ms: (f64, f64),
    /// How far the eye moved since the frame before, metres.
    pub moved_m: f64,
}

/// A frame where the two selections differ.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("frame {frame}: deferred selection differs from full re-evaluation")]
pub struct Differs {
    /// The frame.
    pub frame: usize,
}

/// How many frames a path is flown in: the deferral's work follows the
/// eye's travel per frame, so the rate matters.
#[derive(Clone, Copy, Debug)]
pub enum Pace {
    /// This many frames spread over the path.
    Frames(usize),
    /// The path's own seconds at this many frames a second.
    PerSecond(f64),
}

impl Pace {
    /// Frames for `path` (at least 2).
    pub fn frames(self, path: &CameraPath) -> usize {
        match self {
            Pace::Frames(n) => n.max(2),
            Pace::PerSecond(fps) => ((path.duration_s() * fps).round() as usize + 1).max(2),
        }
    }
}

impl std::fmt::Display for Pace {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match self {
            Pace::Frames(n) => write!(f, "{n} frames a path"),
            Pace::PerSecond(fps) => write!(f, "each path in its own time at {fps} frames/s"),
        }
    }
}

/// How a flight is selected: frames, image size and error threshold (as
/// `sylva fly`'s).
#[derive(Clone, Copy, Debug)]
pub struct Flight {
    /// Frames spread over the path.
    pub frames: usize,
    /// Image size, pixels.
    pub size: (u32, u32),
    /// Error threshold, pixels.
    pub max_error_px: f64,
}

/// Both selectors over `tree` along `path`, frame by frame; an error at
/// the first frame whose tiles differ.
pub fn compare(tree: &TileTree, path: &CameraPath, flight: &Flight) -> Result<Vec<FrameCounts>, Differs> {
    let mut deferred = SseSelector::deferred(tree.clone());
    let mut full = SseSelector::full(tree.clone());
    let mut last_eye = None;
    (0..flight.frames)
        .map(|k| {
            let camera = path.camera(k, flight.frames, flight.size);
            let eye = camera.position_ecef;
            let moved_m = last_eye.replace(eye).map_or(0.0, |e: glam::DVec3| e.distance(eye));
            let (d, d_ms) = timed(&mut deferred, &camera, flight.max_error_px);
            let (f, f_ms) = timed(&mut full, &camera, flight.max_error_px);
            if d.tiles != f.tiles {
                return Err(Differs { frame: k });
            }
            Ok(FrameCounts {
                tiles: d.tiles.len(),
                evaluated: (d.evaluated, f.evaluated),
                touched: (d.visited, f.visited),
                ms: (d_ms, f_ms),
                moved_m,
            })
        })
        .collect()
}

/// One selection and its wall-clock ms.
fn timed(sse: &mut SseSelector, camera: &Camera, max_error_px: f64) -> (Selection, f64) {
    let start = Instant::now();
    let s = sse.select(camera, &LodRule { max_error_px, max_level: crate::grid::TileGrid::MAX_LEVEL });
    (s, start.elapsed().as_secs_f64() * 1e3)
}

/// The table for the demo region and rmnp (`rmnp_config`), every path of
/// `paths_dir` named after its region, flown at `pace`, at `sylva fly`'s
/// defaults (640 × 480, 2 px, level 13).
pub fn report(rmnp_config: &Path, paths_dir: &Path, pace: Pace) -> Result<String, String> {
    let mut rows = Vec::new();
    for (key, config) in [("demo", None), ("rmnp", Some(rmnp_config))] {
        let region = crate::config::load(config).map_err(|e| e.to_string())?;
        let source = RegionSource::new(Arc::new(region));
        let sse = SseSelector::for_source(&source, 13).map_err(|e| e.to_string())?;
        let tree = sse.ok_or("the region's tile tree is too large")?.tree().clone();
        for path_file in paths_of(paths_dir, key)? {
            let path = CameraPath::load(&path_file).map_err(|e| e.to_string())?;
            let flight = Flight { frames: pace.frames(&path), size: (640, 480), max_error_px: 2.0 };
            let counts = compare(&tree, &path, &flight).map_err(|e| format!("{}: {e}", path_file.display()))?;
            let name = path_file.file_stem().map_or(String::new(), |s| s.to_string_lossy().into_owned());
            rows.push(row(&name, tree.nodes.len(), &counts));
        }
    }
    let header = [
        "path",
        "frames",
        "m / frame",
        "tree nodes",
        "tiles",
        "refinement tests, full",
        "deferred",
        "%",
        "nodes touched, full",
        "deferred",
        "%",
        "ms full",
        "ms deferred",
    ];
    Ok(format!(
        "SSE selection along the recorded flyovers, {pace}: 640 × 480, 2 px, level 13; means per frame (the first frame included); the selections are equal in every frame\n\n{}\n",
        table(&header, &rows)
    ))
}

/// The `*.toml` files of `dir` whose names start with `prefix`, sorted.
pub fn paths_of(dir: &Path, prefix: &str) -> Result<Vec<std::path::PathBuf>, String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut files: Vec<_> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            let name = p.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned());
            name.starts_with(prefix) && name.ends_with(".toml")
        })
        .collect();
    files.sort();
    Ok(files)
}

fn row(name: &str, nodes: usize, counts: &[FrameCounts]) -> Vec<String> {
    let n = counts.len().max(1) as f64;
    let mean = |f: &dyn Fn(&FrameCounts) -> f64| counts.iter().map(f).sum::<f64>() / n;
    let percent = |a: f64, b: f64| format!("{:.1}", 100.0 * a / b.max(1.0));
    let (ed, ef) = (mean(&|c| c.evaluated.0 as f64), mean(&|c| c.evaluated.1 as f64));
    let (td, tf) = (mean(&|c| c.touched.0 as f64), mean(&|c| c.touched.1 as f64));
    vec![
        name.to_string(),
        counts.len().to_string(),
        format!("{:.1}", mean(&|c| c.moved_m) * n / (n - 1.0).max(1.0)),
        nodes.to_string(),
        format!("{:.0}", mean(&|c| c.tiles as f64)),
        format!("{ef:.0}"),
        format!("{ed:.0}"),
        percent(ed, ef),
        format!("{tf:.0}"),
        format!("{td:.0}"),
        percent(td, tf),
        format!("{:.3}", mean(&|c| c.ms.1)),
        format!("{:.3}", mean(&|c| c.ms.0)),
    ]
}
