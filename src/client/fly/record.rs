//! What a flight records: one [`FrameRecord`] per frame (`stats.csv`,
//! `docs/stats-csv.md`) and the paragraph that sums a flight up.

use crate::client::render::DrawWork;
use std::collections::BTreeMap;

/// One frame's statistics.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameRecord {
    /// Frame index.
    pub frame: usize,
    /// Selection, loading and preparing tiles, ms.
    pub cpu_ms: f64,
    /// GPU pass time, if measured, ms.
    pub gpu_ms: Option<f64>,
    /// Of that, with rays in a compute pass: the rays' pass and the depth
    /// fill, ms.
    pub gpu_rays_ms: Option<(f64, f64)>,
    /// Encode, submit and wait for the GPU, ms.
    pub render_ms: f64,
    /// Tiles drawn per level.
    pub levels: BTreeMap<u32, u32>,
    /// Tiles ray cast (from the hull or from inside), and drawn plain.
    pub tiles_ray: u32,
    /// Tiles drawn without rays.
    pub tiles_plain: u32,
    /// The error threshold used (raised when the GPU cache was too small;
    /// sse mode).
    pub error_px: Option<f64>,
    /// Pixels where a view ray was cast.
    pub ray_pixels: usize,
    /// Mean and largest view-ray fetches over ray-cast pixels.
    pub view_fetches: (f64, u32),
    /// Mean shadow and shading fetches over ray-cast pixels.
    pub shadow_fetches_mean: f64,
    /// The work of every ray cast, shown or not, over the frame's draws
    /// (counted in held flights under a budget only).
    pub work: Option<DrawWork>,
    /// Bytes fetched from the source during the frame.
    pub bytes_fetched: u64,
    /// Tile bytes resident on the GPU.
    pub gpu_bytes: usize,
    /// Tile bytes held on the CPU.
    pub cpu_bytes: usize,
    /// Resident memory of the process, MiB.
    pub rss_mib: f64,
    /// Selection time, ms.
    pub selection_ms: f64,
    /// The frame budget, ms (budget mode).
    pub budget_ms: Option<f64>,
    /// The frame time the selection predicted, ms, corrected by the
    /// flight's aim ([`BudgetFlight::expected_ms`](crate::client::lod::flight::BudgetFlight::expected_ms); budget mode).
    pub predicted_ms: Option<f64>,
    /// The cost model's prediction for what the frame drew, made before the
    /// frame corrected the model, ms (budget mode): beside `predicted_ms`,
    /// it tells the model's error from what the selection's camera
    /// prediction and aim add.
    pub model_ms: Option<f64>,
    /// Candidate tiles of the selection (budget mode).
    pub candidates: Option<usize>,
    /// The selection's benefit over the optimiser's upper bound (budget
    /// mode).
    pub benefit_bound: Option<f64>,
    /// Mean shadow steps over the tiles drawn.
    pub shadow_steps_mean: f64,
    /// What bounded the selection: [`crate::client::lod::budget::Cut::bound`]
    /// (budget mode).
    pub bound: Option<&'static str>,
    /// Tiles drawn morphing from a coarser one (budget mode).
    pub morphing: Option<usize>,
    /// Trees drawn as splats.
    pub trees: usize,
    /// Tree splats drawn.
    pub splats: usize,
    /// Pixels the splats' quads cover, overlaps counted.
    pub splat_fill_px: f64,
    /// Quadtree nodes the screen-space error selection touched:
    /// refinement and visibility tests (sse mode).
    pub nodes_touched: Option<usize>,
    /// The camera's height above the surface of the finest tile loaded
    /// under it (negative below it), metres; none where none is.
    pub clearance_m: Option<f64>,
    /// The same above its ground, the canopy left out (not in the CSV: a
    /// camera among the trees is below the surface, not the ground).
    pub ground_clearance_m: Option<f64>,
}

/// A one-paragraph summary of a flight: frames, mean and worst times,
/// tiles, fetches, memory at the start and the end; and warnings, among
/// them frames whose tiles had more error than the `asked_error_px`, and
/// why no frame drew a tile, where the source said why it gave none
/// (`no_tile`: [`TileSource::why_no_tile`](crate::client::source::TileSource::why_no_tile)).
pub fn summary(records: &[FrameRecord], asked_error_px: f64, no_tile: Option<&str>) -> String {
    let n = records.len().max(1) as f64;
    let mean = |f: &dyn Fn(&FrameRecord) -> f64| records.iter().map(f).sum::<f64>() / n;
    let gpu: Vec<f64> = records.iter().filter_map(|r| r.gpu_ms).collect();
    let gpu_text = if gpu.is_empty() {
        "no timestamps".to_string()
    } else {
        format!("{:.2} ms GPU", gpu.iter().sum::<f64>() / gpu.len() as f64)
    };
    let (first, last) = (records.first(), records.last());
    // Fetches are counted where frames were read back (`sylva view` reads
    // back none unless under a budget).
    let fetches = if records.iter().any(|r| r.ray_pixels > 0) {
        let max = records.iter().map(|r| r.view_fetches.1).max().unwrap_or(0);
        format!("view fetches/pixel mean {:.1}, max {max}; ", mean(&|r| r.view_fetches.0))
    } else {
        String::new()
    };
    format!(
        "{} frames: {:.2} ms CPU (select + load), {:.2} ms render, {gpu_text} per frame; {:.1} tiles ({:.1} ray cast); {fetches}{} bytes fetched; RSS {:.0} → {:.0} MiB",
        records.len(),
        mean(&|r| r.cpu_ms),
        mean(&|r| r.render_ms),
        mean(&|r| (r.tiles_ray + r.tiles_plain) as f64),
        mean(&|r| r.tiles_ray as f64),
        records.iter().map(|r| r.bytes_fetched).sum::<u64>(),
        first.map_or(0.0, |r| r.rss_mib),
        last.map_or(0.0, |r| r.rss_mib),
    ) + &warnings(records, asked_error_px, no_tile)
}

/// What a flight's frames show that was rarely meant: nothing (and why,
/// where `no_tile` says), the ground from below, or tiles coarser than
/// asked (the GPU cache held no finer cut).
fn warnings(records: &[FrameRecord], asked_error_px: f64, no_tile: Option<&str>) -> String {
    let mut text = String::new();
    let drew = |r: &&FrameRecord| r.tiles_ray + r.tiles_plain > 0;
    // Frames that drew no tile drew none coarser: their selection, knowing
    // no tile's heights, coarsened only its threshold.
    let coarser: Vec<f64> =
        records.iter().filter(drew).filter_map(|r| r.error_px).filter(|&e| e > asked_error_px * 1.001).collect();
    if let Some(worst) = coarser.iter().copied().reduce(f64::max) {
        // Tiles whose box holds the eye (around a pole) have no finite error.
        let drawn = match worst {
            w if w < 10.0 => format!("tiles of up to {worst:.2} px"),
            w if w < 1e5 => format!("tiles of up to {worst:.0} px"),
            _ => "far coarser tiles".to_string(),
        };
        text.push_str(&format!(
            "\nin {} the GPU tile cache held no cut at the asked {asked_error_px} px error, and {drawn} were drawn: a larger --gpu-budget-mib draws finer ones",
            frames(coarser.len()),
        ));
    }
    if !records.is_empty() && !records.iter().any(|r| drew(&r)) {
        let why = no_tile.unwrap_or("does the camera look at the region?");
        text.push_str(&format!("\nno frame drew a tile: {why}"));
    }
    let below: Vec<&FrameRecord> = records.iter().filter(|r| r.ground_clearance_m.is_some_and(|c| c < 0.0)).collect();
    if let (Some(first), Some(deepest)) =
        (below.first(), below.iter().filter_map(|r| r.ground_clearance_m).min_by(f64::total_cmp))
    {
        text.push_str(&format!(
            "\nthe camera is below the ground in {} (from frame {}, as deep as {:.0} m): they show the sky; heights are above the ellipsoid",
            frames(below.len()),
            first.frame,
            -deepest
        ));
    }
    text
}

/// "1 frame", "2 frames".
fn frames(n: usize) -> String {
    if n == 1 { "1 frame".to_string() } else { format!("{n} frames") }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drew(clearance_m: f64, ground_clearance_m: f64) -> FrameRecord {
        FrameRecord {
            tiles_ray: 4,
            clearance_m: Some(clearance_m),
            ground_clearance_m: Some(ground_clearance_m),
            error_px: Some(2.0),
            ..Default::default()
        }
    }

    #[test]
    fn a_camera_among_the_trees_is_not_below_the_ground() {
        // Regression: 12 m above the ground under 20 m crowns was "below
        // the ground … they show the sky".
        let among_trees = [drew(-8.0, 12.0), drew(-8.0, 12.0)];
        assert!(!summary(&among_trees, 2.0, None).contains("below the ground"));
        let under = [drew(-8.0, 12.0), FrameRecord { frame: 1, ..drew(-25.0, -5.0) }];
        assert!(summary(&under, 2.0, None).contains("below the ground in 1 frame (from frame 1, as deep as 5 m)"));
    }

    #[test]
    fn errors_below_a_pixel_are_written_as_such() {
        // Regression: "tiles of up to 0 px were drawn" for an asked 1e-9 px.
        let text = summary(&[FrameRecord { error_px: Some(0.31), ..drew(10.0, 10.0) }], 1e-9, None);
        assert!(text.contains("tiles of up to 0.31 px"), "{text}");
    }

    #[test]
    fn frames_that_drew_no_tile_say_why_and_blame_no_cache() {
        // Regression, from a user's trial: a server without tiles gave "the
        // GPU tile cache held no cut at the asked 2 px error" (the
        // threshold of frames that drew nothing) and a guess at the camera.
        let nothing = [FrameRecord { error_px: Some(57693.0), ..Default::default() }];
        let guessed = summary(&nothing, 2.0, None);
        assert!(guessed.ends_with("\nno frame drew a tile: does the camera look at the region?"), "{guessed}");
        let told = summary(&nothing, 2.0, Some("the server had no tile"));
        assert!(told.ends_with("\nno frame drew a tile: the server had no tile"), "{told}");
    }
}
