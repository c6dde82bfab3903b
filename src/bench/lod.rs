//! `sylva bench lod`: LOD selection time along a flyover, with and without
//! hierarchical variable splitting (000 Figure 3) and with and without the
//! distance deferral table (004 Figure 3), and the benefit reached against
//! the optimiser's upper bound. The predicted-against-measured frame time
//! half (000 Figure 2) needs the renderer.
//!
//! Per frame: tiles are candidates down to where a tile has fewer samples
//! than pixels (beyond, splitting adds no benefit, [`tile_benefit`]); trees
//! are split into variables ([`split`]) or kept one variable per group
//! ("unsplit", the paper's basic method); [`optimize`] selects under a
//! 16 ms budget. The deferral table maintains the same tile cut for a
//! screen-error threshold. Times are wall clock on one thread.

use super::lod_scene::Scene;
use super::table;
use crate::lod::deferral::{ThresholdRefiner, full_refinement};
use crate::lod::model::{CostFeatures, CostModel, Smooth, group_weight, tile_benefit};
use crate::lod::optimizer::{Continuous, Forest, Node, Settings, optimize};
use crate::lod::predict::Cone;
use crate::lod::split::{SplitSettings, Variable, split};
use glam::DVec3;
use std::time::Instant;

/// Samples per tile side in the benefit model.
const TILE_SAMPLES: u32 = 64;
/// Screen: 1920 × 1080, 60° vertical field of view.
const SCREEN_PX: f64 = 1920.0 * 1080.0;
const FOV_Y_RAD: f64 = std::f64::consts::FRAC_PI_3;
/// Ray-casting steps per pixel.
const STEPS: f64 = 16.0;
/// Frame budget, ms.
pub const BUDGET_MS: f64 = 16.0;
/// Acceptable estimated loss of variable splitting in the main run (the
/// sweep in [`sweep`] shows the others).
pub const LOSS_FRACTION: f64 = 0.01;

/// The cost model of the benchmark: 0.5 ms a frame, 4 µs a tile, 0.25 ms a
/// million pixel·steps (view or shadow rays; the scene has no shadows), 30 µs
/// a thousand splats, 5 µs a hundred groups, 50 µs a million pixels of
/// splat fill, 0.1 ms more a million pixel·steps through a fading canopy.
const MODEL: CostModel = CostModel { constants_ms: [0.5, 0.004, 0.25, 0.25, 0.03, 0.005, 0.05, 0.1] };

/// The camera of one frame.
struct Camera {
    /// The cone around the frustum (its half-angle: the diagonal's).
    cone: Cone,
    focal_px: f64,
}

impl Camera {
    fn new(eye: DVec3, forward: DVec3) -> Camera {
        let focal_px = 540.0 / (FOV_Y_RAD / 2.0).tan();
        Camera { cone: Cone::new(eye, forward, (1101.4 / focal_px).atan()), focal_px }
    }

    /// Projected area of a sphere, pixels (capped at the screen), or
    /// `None` if it is outside the view cone.
    fn projected_px(&self, center: DVec3, radius: f64) -> Option<f64> {
        if !self.cone.meets_sphere(center, radius) {
            return None;
        }
        let d = center.distance(self.cone.apex_m());
        let r_px = radius * self.focal_px / (d - radius).max(1.0);
        Some((std::f64::consts::PI * r_px * r_px).min(SCREEN_PX))
    }
}

/// One frame's measurements.
#[derive(Clone, Copy, Debug, Default)]
pub struct Frame {
    /// Candidate tiles given to the optimiser.
    pub tiles: usize,
    /// Continuous variables with splitting.
    pub vars_split: usize,
    /// Continuous variables without splitting (one per visible group).
    pub vars_unsplit: usize,
    /// Selection ms with splitting: tile candidates, splitting, optimiser.
    pub ms_split: f64,
    /// Selection ms without splitting.
    pub ms_unsplit: f64,
    /// Selection ms with splitting, the tile cut kept by the deferral table.
    pub ms_deferred: f64,
    /// Its parts, ms: tile candidates (the deferred refinement included),
    /// variable splitting, the optimiser.
    pub ms_deferred_parts: [f64; 3],
    /// Tiles evaluated by full top-down threshold refinement.
    pub touched_full: usize,
    /// Tiles evaluated by deferred threshold refinement.
    pub touched_deferred: usize,
    /// Ms of full threshold refinement.
    pub ms_refine_full: f64,
    /// Ms of deferred threshold refinement.
    pub ms_refine_deferred: f64,
    /// Benefit with splitting (evaluated per group) over the unsplit
    /// problem's upper bound.
    pub quality_split: f64,
    /// Benefit without splitting over the same bound.
    pub quality_unsplit: f64,
    /// Predicted frame ms of the split selection.
    pub predicted_ms: f64,
    /// Its predicted overrun of the budget, ms.
    pub overrun_ms: f64,
}

/// Runs the flyover of `frames` frames over `scene`, splitting with
/// `loss_fraction`.
pub fn run(scene: &Scene, frames: usize, loss_fraction: f64) -> Vec<Frame> {
    let path = scene.flyover(frames);
    let focal = 540.0 / (FOV_Y_RAD / 2.0).tan();
    // Refine within r + ξ μ ⇔ a tile of size s = 10 ξ has more samples than
    // pixels: d < s · focal / n, so μ = 10 focal / n.
    let mu = 10.0 * focal / f64::from(TILE_SAMPLES);
    let mut refiner = ThresholdRefiner::new(scene.tiles.len(), mu, 1024, scene.ground.side_m / 4.0);
    let mut reference = vec![false; scene.tiles.len()];
    path.iter()
        .map(|&(eye, forward)| {
            let cam = Camera::new(eye, forward);
            let mut f = Frame::default();
            let t = Instant::now();
            f.touched_full = full_refinement(&scene.tiles, mu, eye, &mut reference);
            f.ms_refine_full = ms(t);
            let t = Instant::now();
            f.touched_deferred = refiner.update(&scene.tiles, eye);
            f.ms_refine_deferred = ms(t);
            select(scene, &cam, refiner.refined(), loss_fraction, f)
        })
        .collect()
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Times selection three ways and measures quality.
fn select(scene: &Scene, cam: &Camera, refined: &[bool], loss_fraction: f64, mut f: Frame) -> Frame {
    let t = Instant::now();
    let forest = tile_forest(scene, cam, None);
    let ms_tiles = ms(t);
    let t = Instant::now();
    let deferred_forest = tile_forest(scene, cam, Some(refined));
    let ms_tiles_deferred = ms(t) + f.ms_refine_deferred;
    f.tiles = forest.len();

    let t = Instant::now();
    let split_vars = variables(scene, cam, loss_fraction);
    let continuous_split: Vec<Continuous> = split_vars.iter().map(|v| v.continuous).collect();
    let ms_split_vars = ms(t);
    let t = Instant::now();
    let split_sel = optimize(&forest, &continuous_split, &Settings::budget(BUDGET_MS));
    let ms_opt_split = ms(t);
    let t = Instant::now();
    let _ = optimize(&deferred_forest, &continuous_split, &Settings::budget(BUDGET_MS));
    let ms_opt_deferred = ms(t);

    let t = Instant::now();
    let unsplit_vars = variables(scene, cam, 0.0);
    let continuous_unsplit: Vec<Continuous> = unsplit_vars.iter().map(|v| v.continuous).collect();
    let unsplit_sel = optimize(&forest, &continuous_unsplit, &Settings::budget(BUDGET_MS));
    f.ms_unsplit = ms_tiles + ms(t);

    f.ms_split = ms_tiles + ms_split_vars + ms_opt_split;
    f.ms_deferred = ms_tiles_deferred + ms_split_vars + ms_opt_deferred;
    f.ms_deferred_parts = [ms_tiles_deferred, ms_split_vars, ms_opt_deferred];
    f.vars_split = split_vars.len();
    f.vars_unsplit = unsplit_vars.len();
    let bound = unsplit_sel.upper_bound.max(f64::MIN_POSITIVE);
    f.quality_unsplit = unsplit_sel.benefit / bound;
    let discrete = split_sel.benefit - split_level_benefit(&continuous_split, &split_sel.resolutions);
    f.quality_split = (discrete + spread(scene, &split_vars, &split_sel.resolutions, &unsplit_vars)) / bound;
    f.predicted_ms = MODEL.constants_ms[0] + split_sel.cost_ms;
    f.overrun_ms = split_sel.overrun_ms;
    f
}

/// The tile candidates: from the root down while a tile has more pixels
/// than samples (all of the threshold cut's refined tiles and their
/// children when `refined` is given).
fn tile_forest(scene: &Scene, cam: &Camera, refined: Option<&[bool]>) -> Forest {
    let samples = f64::from(TILE_SAMPLES).powi(2);
    let mut nodes = Vec::new();
    let mut queue = vec![(0u32, None)];
    while let Some((v, parent)) = queue.pop() {
        let tile = &scene.tiles.nodes[v as usize];
        let px = cam.projected_px(tile.center_m, tile.radius_m);
        let (benefit, cost_ms) = match px {
            Some(px) => {
                let work = CostFeatures { tiles: 1.0, raycast_mpx_steps: px * STEPS / 1e6, ..CostFeatures::default() };
                (tile_benefit(px, TILE_SAMPLES, Smooth::default()), MODEL.marginal_ms(&work))
            }
            None => (0.0, 0.0),
        };
        let index = nodes.len() as u32;
        nodes.push(Node { parent, benefit, cost_ms });
        let expand = match refined {
            Some(r) => r[v as usize],
            None => px.is_some_and(|px| px > samples),
        };
        if expand && px.is_some() {
            queue.extend(tile.children().map(|c| (c, Some(index))));
        }
    }
    // Depth-first order keeps parents before children.
    Forest::new(nodes).unwrap_or_default()
}

/// Continuous variables for this frame (`loss_fraction` 0: one per group).
fn variables(scene: &Scene, cam: &Camera, loss_fraction: f64) -> Vec<Variable> {
    let per_splat_ms = MODEL.constants_ms[4] / 1000.0;
    let settings = SplitSettings {
        loss_fraction,
        cost_per_unit_ms: per_splat_ms,
        budget_ms: BUDGET_MS,
        smooth: Smooth::default(),
    };
    let mut weight = |n: &crate::lod::split::ObjectNode| {
        let px = cam.projected_px(n.center_m, n.radius_m).filter(|&px| px >= 1.0)?;
        let per_group = (n.trees / u64::from(n.groups.max(1))) as u32;
        Some(group_weight(px, per_group, 1.0))
    };
    let mut out = Vec::new();
    split(&scene.objects, &mut weight, &settings, &mut out);
    out
}

/// The continuous benefit the optimiser counted.
fn split_level_benefit(vars: &[Continuous], x: &[f64]) -> f64 {
    let smooth = Smooth::default();
    vars.iter().zip(x).map(|(v, x)| v.weight * smooth.phi(x / v.capacity)).sum()
}

/// The split allocation's benefit on the unsplit problem: every group gets
/// its variable's relative resolution.
fn spread(scene: &Scene, split_vars: &[Variable], x: &[f64], unsplit: &[Variable]) -> f64 {
    let mut relative = vec![0.0; scene.items.len()];
    for (v, x) in split_vars.iter().zip(x) {
        let n = &scene.objects.nodes[v.node as usize];
        let u = if n.capacity > 0.0 { x / n.capacity } else { 0.0 };
        relative[n.first as usize..(n.first + n.groups) as usize].fill(u);
    }
    let smooth = Smooth::default();
    unsplit
        .iter()
        .map(|v| v.continuous.weight * smooth.phi(relative[scene.objects.nodes[v.node as usize].first as usize]))
        .sum()
}

/// Median, 95th percentile and maximum.
fn stats(mut v: Vec<f64>) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v.get(((v.len().max(1) - 1) as f64 * q).round() as usize).copied().unwrap_or(f64::NAN);
    (at(0.5), at(0.95), at(1.0))
}

/// The report's tables for one scene.
pub fn report(scene: &Scene, frames: &[Frame]) -> String {
    let col = |f: fn(&Frame) -> f64| stats(frames.iter().map(f).collect());
    let fmt = |(a, b, c): (f64, f64, f64)| vec![format!("{a:.3}"), format!("{b:.3}"), format!("{c:.3}")];
    let row = |name: &str, s: (f64, f64, f64)| [vec![name.to_string()], fmt(s)].concat();
    let mean = |f: fn(&Frame) -> f64| frames.iter().map(f).sum::<f64>() / frames.len().max(1) as f64;
    let touched = |f: fn(&Frame) -> usize| frames.iter().map(|x| f(x) as f64).sum::<f64>();
    let header = format!(
        "### {}: {} tiles, {} tree groups, {} trees, {} frames, budget {BUDGET_MS} ms, splitting loss {LOSS_FRACTION}\n",
        scene.name,
        scene.tiles.len(),
        scene.items.len(),
        scene.trees,
        frames.len()
    );
    let times = table(
        &["per frame", "median", "p95", "max"],
        &[
            row("selection, unsplit (ms)", col(|f| f.ms_unsplit)),
            row("selection, split (ms)", col(|f| f.ms_split)),
            row("selection, split + deferral (ms)", col(|f| f.ms_deferred)),
            row("… tile candidates (ms)", col(|f| f.ms_deferred_parts[0])),
            row("… splitting (ms)", col(|f| f.ms_deferred_parts[1])),
            row("… optimiser (ms)", col(|f| f.ms_deferred_parts[2])),
            row("tile refinement, full (ms)", col(|f| f.ms_refine_full)),
            row("tile refinement, deferred (ms)", col(|f| f.ms_refine_deferred)),
            row("tiles evaluated, full", col(|f| f.touched_full as f64)),
            row("tiles evaluated, deferred", col(|f| f.touched_deferred as f64)),
            row("candidate tiles", col(|f| f.tiles as f64)),
            row("variables, unsplit", col(|f| f.vars_unsplit as f64)),
            row("variables, split", col(|f| f.vars_split as f64)),
            row("benefit / upper bound, unsplit", col(|f| f.quality_unsplit)),
            row("benefit / upper bound, split", col(|f| f.quality_split)),
            row("predicted frame (ms)", col(|f| f.predicted_ms)),
        ],
    );
    let work = touched(|f| f.touched_deferred) / touched(|f| f.touched_full).max(1.0);
    format!(
        "{header}\n{times}\n\nDeferred refinement work: {:.2} % of full re-evaluation; mean benefit/bound {:.4} split, {:.4} unsplit; frames over budget: {}.\n",
        100.0 * work,
        mean(|f| f.quality_split),
        mean(|f| f.quality_unsplit),
        frames.iter().filter(|f| f.overrun_ms > 0.0).count()
    )
}

/// Error against run time of variable splitting: for each acceptable loss,
/// over `frames` frames, the median selection ms and variables and the mean
/// benefit over the bound (0: one variable per group).
pub fn sweep(scene: &Scene, frames: usize) -> String {
    let rows: Vec<Vec<String>> = [0.0, 0.01, 0.05, 0.2, 0.5, 1.0]
        .iter()
        .map(|&loss| {
            let r = run(scene, frames, loss);
            let median = |f: fn(&Frame) -> f64| stats(r.iter().map(f).collect()).0;
            let mean = r.iter().map(|f| f.quality_split).sum::<f64>() / r.len().max(1) as f64;
            vec![
                format!("{loss}"),
                format!("{:.0}", median(|f| f.vars_split as f64)),
                format!("{:.3}", median(|f| f.ms_split)),
                format!("{mean:.4}"),
            ]
        })
        .collect();
    table(&["splitting loss", "variables (median)", "selection ms (median)", "benefit / bound (mean)"], &rows)
}
