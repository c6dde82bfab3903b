//! `sylva fly`: renders a camera path headless, frame by frame — select
//! tiles (by screen-space error, kept across frames by the deferral table,
//! [`super::sse`], or under a frame budget, [`super::lod`]), load the
//! missing ones ([`super::store`]), ray cast them on the GPU — and records per-frame statistics: CPU and GPU
//! time, tiles drawn per level and how, texture fetches per pixel (the ray
//! steps), bytes fetched and memory resident; under a budget also the
//! predicted frame time, which the measured one calibrates, and, asked to,
//! tiles geomorph between levels ([`super::lod::morphs`]). Trees near the
//! camera are drawn as splats ([`super::trees`]): at the resolution their
//! screen size asks for, or under a budget as the selection allots.

mod outputs;

use super::camera::Camera;
use super::lod::ahead::Lookahead;
use super::lod::budget::{Budget, Choice};
use super::lod::flight::BudgetFlight;
use super::lod::steps::FrameSteps;
use super::lod::{Selected, Selector};
use super::path::CameraPath;
use super::quadtree::{self, LodRule};
use super::raycast::{Traversal, TreeBlend};
use super::render::RayPass;
use super::render::uniforms::FrameSettings;
use super::render::{Draw, DrawWork, FrameStats, Readback, RenderError, Rendered, Renderer};
use super::source::TileSource;
use super::sse::SseSelector;
use super::store::{LoadError, TileStore};
use super::tile::TileData;
use super::trees::{self, TreeSettings};
use crate::lod::model::CostModel;
use glam::DVec3;
use outputs::MODEL_FILE;
pub use outputs::{OutDir, STATS_FILE, prepare_out_dir, remove_outputs, to_csv, write_png, write_stats};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// How tiles are chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LodMode {
    /// Refine while the projected error exceeds [`LodRule::max_error_px`].
    Sse,
    /// The most benefit whose predicted frame time fits `budget_ms`.
    Budget {
        /// The frame budget, ms.
        budget_ms: f64,
        /// Frames between selections (the selection period `τ`).
        select_every: u32,
        /// The cost model the flight starts from (one a flight calibrated
        /// on this machine: its `cost_model.json`).
        prior: CostModel,
    },
}

/// Steps of the path sampled for its motion limits (the conservative
/// camera's speed and turn rate).
const MOTION_STEPS: usize = 200;

/// How to fly.
#[derive(Clone, Debug)]
pub struct FlyOptions {
    /// Frames spread evenly over the path.
    pub frames: usize,
    /// Image size, pixels.
    pub size: (u32, u32),
    /// Where frames (`frame_NNNNN.png`) and `stats.csv` go, if anywhere.
    pub out_dir: Option<PathBuf>,
    /// Replace an earlier run's outputs in `out_dir` (else refused).
    pub overwrite: bool,
    /// Write every frame's PNG (else only the statistics).
    pub write_frames: bool,
    /// View-ray traversal.
    pub traversal: Traversal,
    /// Shadow samples per hit (0: no shadows).
    pub shadow_steps: u32,
    /// Tile refinement: the screen-space error rule, and the deepest level
    /// for both modes.
    pub lod: LodRule,
    /// How tiles are chosen.
    pub mode: LodMode,
    /// Geomorph between tile levels (budget mode): a morphing tile is
    /// prepared and uploaded once per morph, and blended on the GPU.
    pub geomorph: bool,
    /// Halo requested with every tile, samples.
    pub halo: usize,
    /// The canopy fade: reference height (m), then low and high (px).
    pub fade: (f64, f64, f64),
    /// Tiles fetched at once, at most.
    pub in_flight: usize,
    /// Trees near the camera as splats (none: the ray-cast canopy only).
    pub trees: Option<TreeSettings>,
    /// Hull quads this many times the tiles' 16 samples
    /// ([`Renderer::with_hull_factor`]; 4 suits software rasterisers).
    pub hull_factor: usize,
    /// Where rays are cast ([`Renderer::with_ray_pass`]).
    pub ray_pass: RayPass,
    /// Each frame is rendered again for this long and its median time
    /// reported and fed to the cost model (0: once): see `held`.
    pub hold_ms: f64,
}

impl Default for FlyOptions {
    fn default() -> Self {
        FlyOptions {
            frames: 60,
            size: (640, 480),
            out_dir: None,
            overwrite: false,
            write_frames: true,
            traversal: Traversal::Exact,
            shadow_steps: 10,
            lod: LodRule { max_error_px: 2.0, max_level: 13 },
            mode: LodMode::Sse,
            geomorph: false,
            halo: 32,
            fade: (30.0, 0.5, 2.0),
            in_flight: 8,
            trees: Some(TreeSettings::default()),
            hull_factor: 1,
            ray_pass: RayPass::Fragment,
            hold_ms: 0.0,
        }
    }
}

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
    /// flight's aim ([`BudgetFlight::expected_ms`]; budget mode).
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
    pub morphing: usize,
    /// Trees drawn as splats.
    pub trees: usize,
    /// Tree splats drawn.
    pub splats: usize,
    /// Pixels the splats' quads cover, overlaps counted.
    pub splat_fill_px: f64,
    /// Quadtree nodes the screen-space error selection touched:
    /// refinement and visibility tests (sse mode).
    pub nodes_touched: Option<usize>,
}

/// Why a flight stopped.
#[derive(Debug, thiserror::Error)]
pub enum FlyError {
    /// A tile could not be loaded.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// The GPU cache cannot hold even the coarsest view, or the frame's
    /// render targets cannot be allocated.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The LOD selection thread could not start.
    #[error("starting the LOD selection thread: {0}")]
    Thread(std::io::Error),
    /// An output file cannot be written (one named as an input found
    /// before the flight starts; a failed write during it).
    #[error(transparent)]
    Output(#[from] crate::outputs::OutputError),
    /// The output directory holds an earlier run's outputs.
    #[error(
        "{0}: holds an earlier flight's or view's outputs ({1}); give another --out, or --overwrite to replace them"
    )]
    Earlier(PathBuf, String),
    /// The flight stopped before its last frame; the frames it finished
    /// and their statistics were written (`kept` says where, or why not).
    #[error("{why}; stopped after {done} of {of} frames{kept}")]
    Stopped {
        /// Why it stopped.
        why: Stop,
        /// Frames finished.
        done: usize,
        /// Frames asked for.
        of: usize,
        /// "; their frames and stats.csv are in DIR", or why not (empty
        /// without an output directory or a frame to keep).
        kept: String,
    },
    /// Writing frames or statistics failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The failure.
        source: std::io::Error,
    },
}

impl FlyError {
    /// The signal (Ctrl-C, SIGTERM) that stopped the flight, if one did.
    pub fn signal(&self) -> Option<i32> {
        match self {
            FlyError::Stopped { why: Stop::Signal(signal), .. } => Some(*signal),
            _ => None,
        }
    }
}

/// Why a flight stopped before its last frame.
#[derive(Debug)]
pub enum Stop {
    /// Ctrl-C or SIGTERM: the signal's number.
    Signal(i32),
    /// An error.
    Failed(Box<FlyError>),
}

impl Stop {
    fn failed(e: FlyError) -> Stop {
        Stop::Failed(Box::new(e))
    }
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Stop::Signal(signal) => write!(f, "interrupted by signal {signal}"),
            Stop::Failed(e) => e.fmt(f),
        }
    }
}

/// Flies `path` over `source`, rendering with `renderer`. A flight that
/// stops early, by an error or by Ctrl-C or SIGTERM, writes the statistics
/// of the frames it finished beside their PNGs and says so
/// ([`FlyError::Stopped`]).
pub fn fly(
    source: &dyn TileSource,
    path: &CameraPath,
    renderer: &mut Renderer,
    options: &FlyOptions,
) -> Result<Vec<FrameRecord>, FlyError> {
    let mut out = match &options.out_dir {
        Some(dir) => prepare_out_dir(dir, options.overwrite)?,
        None => OutDir::default(),
    };
    // A budget flight replaces the cost model at its end, whole: until
    // then it may be the model this flight started from.
    if matches!(options.mode, LodMode::Budget { .. }) {
        out.earlier.retain(|f| !f.ends_with(MODEL_FILE));
    }
    let flown = fly_in(source, path, renderer, options, std::mem::take(&mut out.earlier));
    if flown.is_err() {
        // Directories made for the flight and left empty go.
        out.remove_made();
    }
    flown
}

/// [`fly`] in its output directory, which holds `earlier` outputs.
fn fly_in(
    source: &dyn TileSource,
    path: &CameraPath,
    renderer: &mut Renderer,
    options: &FlyOptions,
    mut earlier: Vec<PathBuf>,
) -> Result<Vec<FrameRecord>, FlyError> {
    let frame_s = path.time(1, options.frames) - path.time(0, options.frames);
    let motion = Motion { frame_s, limits: path.motion_limits(MOTION_STEPS), shadows: path.sun.is_some() };
    let mut flight = Flight::new(source, renderer, options, motion)?;
    let mut records = Vec::with_capacity(options.frames);
    // Watched until the results are written: a first Ctrl-C then waits.
    let interrupt = crate::interrupt::Interrupt::watch();
    let flown = fly_path(&mut flight, (source, path, renderer), options, (&mut earlier, &mut records), &interrupt);
    // A frame that failed because of the signal (a server in the same
    // process group stopped by it) was stopped by the signal.
    let stopped = flown.err().map(|why| interrupt.came().map_or(why, Stop::Signal));
    let model = flight.model();
    match (stopped, &options.out_dir) {
        (None, Some(dir)) => outputs::write_results(dir, &records, model.as_ref()).map(|()| records),
        (None, None) => Ok(records),
        // Nothing done, nothing written: an earlier run's outputs are whole.
        (Some(Stop::Failed(e)), _) if records.is_empty() => Err(*e),
        (Some(why), dir) => {
            let kept = match dir.as_deref().filter(|_| !records.is_empty()) {
                Some(dir) => outputs::keep(dir, &records, model.as_ref(), options.write_frames),
                None => String::new(),
            };
            Err(FlyError::Stopped { why, done: records.len(), of: options.frames, kept })
        }
    }
}

/// Renders the path's frames, each one's PNG written once it is done, and
/// keeps their records, until the last frame, an error, or Ctrl-C or
/// SIGTERM (after the frame in hand; a second signal ends the process).
fn fly_path(
    flight: &mut Flight,
    (source, path, renderer): (&dyn TileSource, &CameraPath, &mut Renderer),
    options: &FlyOptions,
    (earlier, records): (&mut Vec<PathBuf>, &mut Vec<FrameRecord>),
    interrupt: &crate::interrupt::Interrupt,
) -> Result<(), Stop> {
    for k in 0..options.frames {
        if let Some(signal) = interrupt.came() {
            return Err(Stop::Signal(signal));
        }
        let shot = Shot {
            index: k,
            t_s: path.time(k, options.frames),
            camera: path.camera(k, options.frames, options.size),
            sun_ecef: path.sun_ecef(),
        };
        let framed = flight.frame(source, renderer, options, &shot, Readback::All).map_err(Stop::failed)?;
        let png =
            options.out_dir.as_ref().filter(|_| options.write_frames).map(|d| d.join(format!("frame_{k:05}.png")));
        if let Some(png) = &png {
            write_png(png, &framed.rendered, options.size).map_err(Stop::failed)?;
        }
        // The earlier run's outputs go once this one has a frame to show
        // (written: its PNG replaced the earlier one of the same name).
        earlier.retain(|f| Some(f) != png.as_ref());
        remove_outputs(&std::mem::take(earlier)).map_err(Stop::failed)?;
        records.push(framed.record);
    }
    Ok(())
}

/// The mean of `values`; 0 (not the −0 an empty sum is) for none.
fn mean_or_zero(values: impl ExactSizeIterator<Item = f64>) -> f64 {
    match values.len() {
        0 => 0.0,
        n => values.sum::<f64>() / n as f64,
    }
}

/// How the camera of a flight moves: what a budget flight's selections
/// look ahead by.
#[derive(Clone, Copy, Debug)]
pub struct Motion {
    /// Seconds between frames.
    pub frame_s: f64,
    /// The fastest the camera moves and turns.
    pub limits: crate::lod::predict::MotionLimits,
    /// Whether the sun is on (shadow rays are priced).
    pub shadows: bool,
}

/// What a budget flight's selections, made every `select_every` frames,
/// look ahead by.
fn lookahead(select_every: u32, motion: &Motion) -> Lookahead {
    Lookahead { tau_s: motion.frame_s * f64::from(select_every.max(1)), limits: motion.limits }
}

/// One frame to render: its camera, its time and its sun.
#[derive(Clone, Copy, Debug)]
pub struct Shot {
    /// Frame index, for its record.
    pub index: usize,
    /// Time, seconds of the flight.
    pub t_s: f64,
    /// The camera.
    pub camera: Camera,
    /// Unit direction to the sun (ECEF), if it is on.
    pub sun_ecef: Option<DVec3>,
}

/// A rendered frame: its statistics, its images and the tiles it drew.
pub struct Framed {
    /// The statistics.
    pub record: FrameRecord,
    /// The images read back.
    pub rendered: Rendered,
    /// The tiles drawn.
    pub tiles: Vec<Arc<TileData>>,
}

/// What a flight keeps from frame to frame: the tiles loaded on the CPU and
/// the selection's state (the deferral table, or the budget flight with its
/// selection thread and calibrated cost model).
pub struct Flight {
    store: TileStore,
    lod: Option<BudgetFlight>,
    sse: Option<SseSelector>,
}

impl Flight {
    /// A flight over `source` rendered by `renderer` whose camera moves as
    /// `motion` says.
    pub fn new(
        source: &dyn TileSource,
        renderer: &Renderer,
        options: &FlyOptions,
        motion: Motion,
    ) -> Result<Flight, FlyError> {
        let budget = 2 * renderer.cache_slots() as usize * slot_estimate(source, options.halo);
        let store = TileStore::new(options.halo, budget, options.in_flight)?;
        let sse = match options.mode {
            LodMode::Sse => SseSelector::for_source(source, options.lod.max_level).map_err(LoadError::from)?,
            LodMode::Budget { .. } => None,
        };
        let lod = match options.mode {
            LodMode::Sse => None,
            LodMode::Budget { budget_ms, select_every, prior } => {
                let selector = Selector {
                    grid: source.grid(),
                    bounds: source.bounds(),
                    knowledge: store.knowledge(),
                    fade: options.fade,
                    trees: options.trees,
                    max_level: options.lod.max_level,
                };
                let budget = Budget {
                    budget_ms,
                    max_tiles: renderer.cache_slots() as usize,
                    shadows: motion.shadows,
                    deadline: None,
                };
                let look = lookahead(select_every, &motion);
                Some(BudgetFlight::new(selector, budget, look, prior, options.geomorph).map_err(FlyError::Thread)?)
            }
        };
        Ok(Flight { store, lod, sse })
    }

    /// From now on loads tiles in the background: a frame draws the tiles
    /// here, their nearest loaded ancestors standing in for the rest
    /// ([`TileStore::load_in_background`]).
    pub fn load_in_background(&mut self, source: Arc<dyn TileSource>) -> Result<(), FlyError> {
        Ok(self.store.load_in_background(source)?)
    }

    /// Tiles loading in the background.
    pub fn pending(&self) -> usize {
        self.store.pending()
    }

    /// Tile loads that failed in the background (each is tried again).
    pub fn failures(&self) -> usize {
        self.store.failures()
    }

    /// The cost model a budget flight has calibrated so far.
    pub fn model(&self) -> Option<CostModel> {
        self.lod.as_ref().map(BudgetFlight::model)
    }

    /// The camera moves as `motion` says from now on (a budget flight's
    /// selections look ahead by it).
    pub fn set_motion(&mut self, options: &FlyOptions, motion: Motion) {
        if let (Some(lod), LodMode::Budget { select_every, .. }) = (&mut self.lod, options.mode) {
            lod.set_motion(lookahead(select_every, &motion), motion.shadows);
        }
    }

    /// The finest tile held that contains the point `(lon, lat)`, degrees.
    pub fn tile_at(&self, grid: &crate::grid::TileGrid, lon: f64, lat: f64) -> Option<Arc<TileData>> {
        self.store.finest_at(grid, lon, lat)
    }

    /// Selects, loads and renders `shot`, reading back what `readback` asks
    /// (everything under a budget, whose cost model learns from the
    /// frame's fetches).
    pub fn frame(
        &mut self,
        source: &dyn TileSource,
        renderer: &mut Renderer,
        options: &FlyOptions,
        shot: &Shot,
        readback: Readback,
    ) -> Result<Framed, FlyError> {
        let readback = if self.lod.is_some() { Readback::All } else { readback };
        // Counted where the times come from other, uncounted renders of the
        // frame (the counters would weigh on the times the model learns).
        renderer.count_work(self.lod.is_some() && options.hold_ms > 0.0);
        frame(source, renderer, (&mut self.store, self.lod.as_mut(), self.sse.as_mut()), options, (shot, readback))
    }
}

/// The tiles of one frame and how they were chosen.
struct Chosen {
    tiles: Vec<Arc<TileData>>,
    /// Shadow steps per tile, in the order of `tiles`.
    steps: Vec<u32>,
    /// Morph weight of each tile's own heights (1: not morphing).
    weights: Vec<f32>,
    error_px: Option<f64>,
    selected: Option<Selected>,
    /// Tiles drawn morphing from a coarser one.
    morphing: usize,
    /// Nodes the screen-space error selection touched.
    touched: Option<usize>,
    /// Time of the selection, ms.
    selection_ms: f64,
}

/// The frame's tiles: by screen-space error, or under the budget.
fn choose(
    source: &dyn TileSource,
    (store, lod, sse): (&mut TileStore, Option<&mut BudgetFlight>, Option<&mut SseSelector>),
    (t_s, camera): (f64, &Camera),
    (options, slots): (&FlyOptions, u32),
) -> Result<Chosen, FlyError> {
    let Some(lod) = lod else {
        let Visible { tiles, error_px, touched, selection_ms } =
            visible_tiles(source, store, sse, camera, options, slots)?;
        let (steps, weights) = (vec![options.shadow_steps; tiles.len()], vec![1.0; tiles.len()]);
        let (error_px, touched, selected) = (Some(error_px), Some(touched), None);
        return Ok(Chosen { tiles, steps, weights, error_px, selected, morphing: 0, touched, selection_ms });
    };
    let selected = lod.frame(t_s, camera);
    let ids: Vec<_> = selected.cut.tiles.iter().map(|c| c.id).collect();
    let mut tiles = store.get_cut(source, &ids)?;
    let drawn: Vec<_> = tiles.iter().map(|t| t.id()).collect();
    let morphing = lod.morphs(t_s, &drawn);
    let mut weights = vec![1.0; tiles.len()];
    for m in &morphing {
        let (Some(k), Some(from)) = (drawn.iter().position(|&id| id == m.tile), store.get(source, &[m.from])?.pop())
        else {
            continue;
        };
        // Kept while its morph lasts; at weight 1 the tile shows its own
        // surface, which it draws cheaper alone (one texture read per
        // height, its own bounds: 0.75× the view and 0.5× the shadow
        // fetches of the pair in the demo's four-tile view).
        let pair = lod.morph_tile(&source.grid(), &tiles[k], &from);
        if m.weight < 1.0 {
            tiles[k] = pair;
            weights[k] = m.weight as f32;
        }
    }
    let steps_of: std::collections::HashMap<_, _> = selected.cut.tiles.iter().map(|c| (c.id, c.shadow_steps)).collect();
    // A loaded ancestor standing in for tiles still loading takes the most
    // shadow steps the selection gave any tile.
    let most = selected.cut.tiles.iter().map(|c| c.shadow_steps).max().unwrap_or(0);
    let steps = tiles.iter().map(|t| steps_of.get(&t.id()).copied().unwrap_or(most)).collect();
    let morphing = weights.iter().filter(|&&w| w < 1.0).count();
    let selection_ms = selected.ms;
    Ok(Chosen {
        tiles,
        steps,
        weights,
        error_px: None,
        selected: Some(selected),
        morphing,
        touched: None,
        selection_ms,
    })
}

fn frame(
    source: &dyn TileSource,
    renderer: &mut Renderer,
    (store, mut lod, sse): (&mut TileStore, Option<&mut BudgetFlight>, Option<&mut SseSelector>),
    options: &FlyOptions,
    (shot, readback): (&Shot, Readback),
) -> Result<Framed, FlyError> {
    let start = Instant::now();
    let bytes_before = source.bytes_fetched();
    let (camera, t_s) = (shot.camera, shot.t_s);
    let mut chosen =
        choose(source, (store, lod.as_deref_mut(), sse), (t_s, &camera), (options, renderer.cache_slots()))?;
    if shot.sun_ecef.is_none() {
        // No sun, no shadow rays: none drawn, none priced.
        chosen.steps.fill(0);
    }
    let (tiles, error_px) = (&chosen.tiles, chosen.error_px);
    let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
    let fade = trees::canopy_fade(options.fade, options.trees.as_ref(), camera.focal_px());
    let settings = FrameSettings {
        traversal: options.traversal,
        shadow_steps: options.shadow_steps,
        sun_ecef: shot.sun_ecef,
        fade,
    };
    let budgets = chosen.selected.as_ref().map(|s| &s.cut.tree_budgets);
    let trees = tree_splats(options, tiles, &camera, (&fade.trees, budgets));
    if let Some(lod) = lod.as_deref_mut().filter(|_| options.trees.is_some()) {
        lod.set_drawn(tiles.clone());
    }
    let draws: Vec<Draw> = (0..tiles.len())
        .map(|k| Draw {
            tile: tiles[k].as_ref(),
            shadow_steps: chosen.steps[k],
            splats: &trees.splats[k],
            morph_weight: chosen.weights[k],
        })
        .collect();
    let mut out = renderer.render_draws(&camera, &draws, &settings, readback)?;
    if options.hold_ms > 0.0 {
        let held = held(renderer, (&camera, &draws, &settings), options.hold_ms)?;
        (out.stats.gpu_ms, out.stats.gpu_rays_ms, out.stats.wall_ms) = (held.gpu_ms, held.gpu_rays_ms, held.wall_ms);
    }
    let selected = chosen.selected.as_ref();
    let predicted_ms = lod.as_deref().zip(selected).map(|(l, s)| l.expected_ms(s));
    let budget_ms = lod.as_deref().map(|l| l.budget().budget_ms);
    let drawn: Vec<Choice> = draws.iter().map(|d| Choice { id: d.tile.id(), shadow_steps: d.shadow_steps }).collect();
    let steps = FrameSteps::measure(&out.fetches, &out.draws, &drawn);
    let model_ms = lod.map(|lod| {
        lod.observe(&camera, &drawn, &trees.drawn, (out.stats.gpu_ms.unwrap_or(out.stats.wall_ms), &steps)).model_ms
    });
    let mut levels = BTreeMap::new();
    for t in tiles {
        *levels.entry(t.id().level).or_insert(0) += 1;
    }
    let rays: Vec<&[u32; 2]> = out.fetches.iter().filter(|f| f[0] > 0).collect();
    let record = FrameRecord {
        frame: shot.index,
        cpu_ms,
        gpu_ms: out.stats.gpu_ms,
        gpu_rays_ms: out.stats.gpu_rays_ms,
        render_ms: out.stats.wall_ms,
        levels,
        tiles_ray: out.stats.tiles_hull + out.stats.tiles_inside,
        tiles_plain: out.stats.tiles_plain,
        error_px,
        ray_pixels: rays.len(),
        view_fetches: (steps.view.mean.unwrap_or(0.0), rays.iter().map(|f| f[0]).max().unwrap_or(0)),
        shadow_fetches_mean: mean_or_zero(rays.iter().map(|f| f64::from(f[1]))),
        work: (!out.work.is_empty()).then(|| out.work.iter().fold(DrawWork::default(), |a, w| a.plus(w))),
        bytes_fetched: source.bytes_fetched() - bytes_before,
        gpu_bytes: out.stats.resident_bytes,
        cpu_bytes: store.bytes(),
        rss_mib: crate::bench::rss_mib().0,
        selection_ms: chosen.selection_ms,
        budget_ms,
        predicted_ms,
        model_ms,
        candidates: selected.map(|s| s.candidates),
        benefit_bound: selected.map(|s| s.cut.share_of_bound()),
        bound: selected.map(|s| s.cut.bound()),
        morphing: chosen.morphing,
        nodes_touched: chosen.touched,
        shadow_steps_mean: mean_or_zero(chosen.steps.iter().map(|&s| f64::from(s))),
        trees: trees.drawn.trees,
        splats: out.stats.splats as usize,
        splat_fill_px: trees.drawn.fill_px,
    };
    Ok(Framed { record, rendered: out, tiles: chosen.tiles })
}

/// A frame's trees.
#[derive(Default)]
struct FrameTrees {
    /// Splats, a list per tile.
    splats: Vec<Vec<trees::Splat>>,
    drawn: trees::Drawn,
}

/// The trees near the camera on `tiles`, by screen size or, under a
/// budget, with the selection's splat budgets.
fn tree_splats(
    options: &FlyOptions,
    tiles: &[Arc<TileData>],
    camera: &Camera,
    (blend, budgets): (&TreeBlend, Option<&trees::TreeBudgets>),
) -> FrameTrees {
    let mut out = FrameTrees { splats: vec![Vec::new(); tiles.len()], ..FrameTrees::default() };
    let Some(settings) = &options.trees else { return out };
    let refs: Vec<&TileData> = tiles.iter().map(|t| t.as_ref()).collect();
    let groups = trees::groups_near(settings, &refs, camera, blend);
    out.drawn = trees::splats(settings, &groups, budgets, (blend, camera.focal_px()), &mut out.splats);
    out
}

/// The frame's tiles by screen-space error, and what choosing them took.
pub struct Visible {
    /// The tiles, loaded.
    pub tiles: Vec<Arc<TileData>>,
    /// The error threshold that made them fit the GPU cache, pixels.
    pub error_px: f64,
    /// Quadtree nodes the selections touched.
    pub touched: usize,
    /// Time of the selections alone (not the loading), ms.
    pub selection_ms: f64,
}

/// The frame's tiles, coarsening the error threshold until they fit the
/// GPU cache: by a flight's `sse` selector, or by the stateless walk.
pub fn visible_tiles(
    source: &dyn TileSource,
    store: &mut TileStore,
    mut sse: Option<&mut SseSelector>,
    camera: &Camera,
    options: &FlyOptions,
    slots: u32,
) -> Result<Visible, FlyError> {
    let mut rule = options.lod;
    let (mut touched, start) = (0, Instant::now());
    loop {
        let selection = match sse.as_deref_mut() {
            Some(sse) => sse.select(camera, rule.max_error_px),
            None => quadtree::select(&source.grid(), &source.bounds(), camera, &|id| store.range(id), &rule),
        };
        touched += selection.visited;
        if selection.tiles.len() <= slots as usize || rule.max_error_px > 1e6 {
            let selection_ms = start.elapsed().as_secs_f64() * 1e3;
            let ids: Vec<_> = selection.tiles.iter().map(|s| s.id).collect();
            let tiles = store.get_cut(source, &ids)?;
            return Ok(Visible { tiles, error_px: rule.max_error_px, touched, selection_ms });
        }
        rule.max_error_px *= 1.25;
    }
}

/// Bytes of one prepared tile, for the CPU store's budget.
fn slot_estimate(source: &dyn TileSource, halo: usize) -> usize {
    let side = source.grid().samples() as usize + 2 * halo;
    side * side * 26
}

/// The times of a frame's draws rendered again and again for `hold_ms`,
/// of the render with the median GPU (or wall) time: what a loop rendering
/// continuously sees, on a GPU that lowers its clocks while it waits for a
/// CPU-bound flight's next frame.
fn held(
    renderer: &mut Renderer,
    (camera, draws, settings): (&Camera, &[Draw], &FrameSettings),
    hold_ms: f64,
) -> Result<FrameStats, FlyError> {
    let start = Instant::now();
    let mut renders = Vec::new();
    while renders.is_empty() || start.elapsed().as_secs_f64() * 1e3 < hold_ms {
        renders.push(renderer.render_draws(camera, draws, settings, Readback::None)?.stats);
    }
    let ms = |s: &FrameStats| s.gpu_ms.unwrap_or(s.wall_ms);
    renders.sort_by(|a, b| ms(a).total_cmp(&ms(b)));
    Ok(renders[renders.len() / 2])
}

/// A one-paragraph summary of a flight: frames, mean and worst times,
/// tiles, fetches, memory at the start and the end.
pub fn summary(records: &[FrameRecord]) -> String {
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
    ) + if !records.is_empty() && records.iter().all(|r| r.tiles_ray + r.tiles_plain == 0) {
        // Blank frames are no error, but rarely what was meant.
        "\nno frame drew a tile: does the camera look at the region?"
    } else {
        ""
    }
}

/// Parses `exact` or `linear:STEPS`.
pub fn parse_traversal(text: &str) -> Option<Traversal> {
    match text.split_once(':') {
        None if text.eq_ignore_ascii_case("exact") => Some(Traversal::Exact),
        Some((kind, steps)) if kind.eq_ignore_ascii_case("linear") => {
            steps.parse().ok().filter(|&s| s > 0).map(Traversal::Linear)
        }
        _ => None,
    }
}

/// Opens the GPU and flies: what `sylva fly` does.
pub fn run(
    source: &dyn TileSource,
    path: &CameraPath,
    options: &FlyOptions,
    gpu_budget_bytes: usize,
) -> Result<Vec<FrameRecord>, RunError> {
    let gpu = super::render::gpu::Gpu::open()?;
    let grid = source.grid();
    let mut renderer = Renderer::new(gpu, grid.samples(), options.halo as u32, gpu_budget_bytes, options.geomorph)?
        .with_hull_factor(options.hull_factor)
        .with_ray_pass(options.ray_pass);
    Ok(fly(source, path, &mut renderer, options)?)
}

/// Why `sylva fly` failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// No GPU.
    #[error(transparent)]
    Gpu(#[from] super::render::gpu::GpuError),
    /// The GPU has not the memory for the tile cache.
    #[error(transparent)]
    Alloc(#[from] super::render::gpu::AllocError),
    /// The flight failed.
    #[error(transparent)]
    Fly(#[from] FlyError),
}

impl RunError {
    /// The signal (Ctrl-C, SIGTERM) that stopped the flight, if one did.
    pub fn signal(&self) -> Option<i32> {
        match self {
            RunError::Fly(e) => e.signal(),
            _ => None,
        }
    }
}
