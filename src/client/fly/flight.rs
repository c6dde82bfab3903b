//! One frame of a flight: the tiles chosen (by screen-space error or under
//! the budget), loaded, given their trees and shadow steps, rendered, and
//! the frame's statistics recorded; a [`Flight`] keeps what carries from
//! frame to frame.

use super::{FlyError, FlyOptions, FrameRecord, LodMode};
use crate::client::camera::Camera;
use crate::client::envelope::HeightEnvelope;
use crate::client::globe::Geodetic;
use crate::client::lod::ahead::Lookahead;
use crate::client::lod::budget::{Budget, Choice};
use crate::client::lod::flight::BudgetFlight;
use crate::client::lod::steps::FrameSteps;
use crate::client::lod::{Selected, Selector};
use crate::client::quadtree;
use crate::client::raycast::TreeBlend;
use crate::client::render::uniforms::FrameSettings;
use crate::client::render::{Draw, DrawWork, FrameStats, Readback, Rendered, Renderer};
use crate::client::source::TileSource;
use crate::client::sse::SseSelector;
use crate::client::store::TileStore;
use crate::client::tile;
use crate::client::tile::TileData;
use crate::client::trees;
use crate::grid::TileId;
use crate::lod::model::CostModel;
use glam::DVec3;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

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
/// look ahead by: at most [`MAX_LOOKAHEAD_S`].
fn lookahead(select_every: u32, motion: &Motion) -> Lookahead {
    let tau_s = (motion.frame_s * f64::from(select_every.max(1))).min(MAX_LOOKAHEAD_S);
    Lookahead { tau_s, limits: motion.limits }
}

/// The longest a selection looks ahead, seconds: a flight of few frames
/// far apart selects for each frame's own view (a conservative camera over
/// their whole gap would cover most of the region, and the cut would be
/// coarse everywhere).
const MAX_LOOKAHEAD_S: f64 = 1.0;

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
    /// The coarse tiles' heights.
    envelope: Arc<HeightEnvelope>,
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
        let mut store = TileStore::new(options.halo, budget, options.in_flight)?;
        // Some tile under the camera wherever it flies over the region, for
        // its clearance; the view's background loading holds them too.
        let envelope = store.hold_coarse(source)?;
        let sse = match options.mode {
            LodMode::Sse => SseSelector::over(&source.grid(), &source.bounds(), &envelope, options.lod.max_level),
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
                    // A selection never takes longer than the frame it is for.
                    time_limit: Duration::try_from_secs_f64(budget_ms / 1e3).ok(),
                };
                let look = lookahead(select_every, &motion);
                Some(BudgetFlight::new(selector, budget, look, prior, options.geomorph).map_err(FlyError::Thread)?)
            }
        };
        Ok(Flight { store, lod, sse, envelope })
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

    /// The heights of the coarse tiles over the region, which bound every
    /// finer tile's.
    pub fn envelope(&self) -> &HeightEnvelope {
        &self.envelope
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

/// A cut's tiles with those under a tile still morphing held back
/// ([`BudgetFlight::held_cut`]): that tile is drawn instead, if the store
/// still holds it (the store loads and keeps the cut as selected).
fn held_back(store: &mut TileStore, lod: &BudgetFlight, tiles: Vec<Arc<TileData>>) -> Vec<Arc<TileData>> {
    let ids: Vec<TileId> = tiles.iter().map(|t| t.id()).collect();
    let held = lod.held_cut(&ids);
    if held == ids {
        return tiles;
    }
    let find = |store: &mut TileStore, id| tiles.iter().find(|t| t.id() == id).cloned().or_else(|| store.touch(id));
    held.into_iter().map(|id| find(store, id)).collect::<Option<Vec<_>>>().unwrap_or(tiles)
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
    /// Tiles drawn morphing from a coarser one (budget mode).
    morphing: Option<usize>,
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
        return Ok(Chosen { tiles, steps, weights, error_px, selected, morphing: None, touched, selection_ms });
    };
    let selected = lod.frame(t_s, camera);
    let ids: Vec<_> = selected.cut.tiles.iter().map(|c| c.id).collect();
    let cut = store.get_cut(source, &ids)?;
    let mut tiles = held_back(store, lod, cut);
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
    let morphing = Some(weights.iter().filter(|&&w| w < 1.0).count());
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
    let camera = shot.camera;
    let mut chosen =
        choose(source, (store, lod.as_deref_mut(), sse), (shot.t_s, &camera), (options, renderer.cache_slots()))?;
    if shot.sun_ecef.is_none() {
        // No sun, no shadow rays: none drawn, none priced.
        chosen.steps.fill(0);
    }
    let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
    let drawn = draw(renderer, &mut chosen, lod.as_deref_mut(), options, (shot, readback))?;
    let budget = lod.map(|lod| {
        // Expected before the frame moves the aim.
        let predicted_ms = chosen.selected.as_ref().map(|s| lod.expected_ms(s));
        let frame_ms = drawn.out.stats.gpu_ms.unwrap_or(drawn.out.stats.wall_ms);
        let model_ms = lod.observe(&camera, &drawn.choices, &drawn.trees.drawn, (frame_ms, &drawn.steps)).model_ms;
        (lod.budget().budget_ms, predicted_ms, model_ms)
    });
    let frame = Frame {
        shot,
        cpu_ms,
        bytes_fetched: source.bytes_fetched() - bytes_before,
        cpu_bytes: store.bytes(),
        clearance_m: clearance_m(source, store, &camera),
        budget,
    };
    Ok(Framed { record: record(&frame, &chosen, &drawn), rendered: drawn.out, tiles: chosen.tiles })
}

/// A frame drawn: what the renderer returned, its trees, each tile as
/// drawn, and the view-ray steps it measured.
struct Drawn {
    out: Rendered,
    trees: FrameTrees,
    choices: Vec<Choice>,
    steps: FrameSteps,
}

/// Draws the tiles `chosen` with their trees (under a budget, the cut
/// drawn takes the trees' prices: `chosen.selected` becomes it), held for
/// `options.hold_ms` where asked.
fn draw(
    renderer: &mut Renderer,
    chosen: &mut Chosen,
    mut lod: Option<&mut BudgetFlight>,
    options: &FlyOptions,
    (shot, readback): (&Shot, Readback),
) -> Result<Drawn, FlyError> {
    let (camera, tiles) = (&shot.camera, &chosen.tiles);
    let mut fade = trees::canopy_fade(options.fade, options.trees.as_ref(), camera.focal_px());
    let mut trees = tree_splats(options, tiles, camera, &fade.trees, lod.as_deref_mut());
    if options.trees.is_some() {
        fade.trees = trees.drawn.blend;
    }
    let settings = FrameSettings {
        traversal: options.traversal,
        shadow_steps: options.shadow_steps,
        sun_ecef: shot.sun_ecef,
        fade,
    };
    if let Some(lod) = lod.filter(|_| options.trees.is_some()) {
        lod.set_drawn(tiles.clone());
    }
    if let Some(priced) = trees.priced.take() {
        chosen.selected = Some(priced);
    }
    let draws: Vec<Draw> = (0..tiles.len())
        .map(|k| Draw {
            tile: tiles[k].as_ref(),
            shadow_steps: chosen.steps[k],
            splats: &trees.splats[k],
            morph_weight: chosen.weights[k],
        })
        .collect();
    let mut out = renderer.render_draws(camera, &draws, &settings, readback)?;
    if options.hold_ms > 0.0 {
        let held = held(renderer, (camera, &draws, &settings), options.hold_ms)?;
        (out.stats.gpu_ms, out.stats.gpu_rays_ms, out.stats.wall_ms) = (held.gpu_ms, held.gpu_rays_ms, held.wall_ms);
    }
    let choice = |d: &Draw| Choice { id: d.tile.id(), shadow_steps: d.shadow_steps, morphs: d.morph_weight < 1.0 };
    let choices: Vec<Choice> = draws.iter().map(choice).collect();
    let steps = FrameSteps::measure(&out.fetches, &out.draws, &choices);
    Ok(Drawn { out, trees, choices, steps })
}

/// What a frame measured outside its render.
struct Frame<'a> {
    shot: &'a Shot,
    cpu_ms: f64,
    bytes_fetched: u64,
    cpu_bytes: usize,
    /// Above the surface and above the ground.
    clearance_m: (Option<f64>, Option<f64>),
    /// Under a budget: the budget, the cut's expected time, and the model's
    /// prediction for what was drawn, ms.
    budget: Option<(f64, Option<f64>, f64)>,
}

/// The statistics of a frame that drew `drawn`, the tiles `chosen`.
fn record(frame: &Frame, chosen: &Chosen, drawn: &Drawn) -> FrameRecord {
    let (out, selected) = (&drawn.out, chosen.selected.as_ref());
    let mut levels = BTreeMap::new();
    for t in &chosen.tiles {
        *levels.entry(t.id().level).or_insert(0) += 1;
    }
    let rays: Vec<&[u32; 2]> = out.fetches.iter().filter(|f| f[0] > 0).collect();
    FrameRecord {
        frame: frame.shot.index,
        cpu_ms: frame.cpu_ms,
        gpu_ms: out.stats.gpu_ms,
        gpu_rays_ms: out.stats.gpu_rays_ms,
        render_ms: out.stats.wall_ms,
        levels,
        tiles_ray: out.stats.tiles_hull + out.stats.tiles_inside,
        tiles_plain: out.stats.tiles_plain,
        error_px: chosen.error_px,
        ray_pixels: rays.len(),
        // Over every ray-cast pixel, morph pairs too (the steps measured
        // for pricing keep those apart).
        view_fetches: (
            mean_or_zero(rays.iter().map(|f| f64::from(f[0]))),
            rays.iter().map(|f| f[0]).max().unwrap_or(0),
        ),
        shadow_fetches_mean: mean_or_zero(rays.iter().map(|f| f64::from(f[1]))),
        work: (!out.work.is_empty()).then(|| out.work.iter().fold(DrawWork::default(), |a, w| a.plus(w))),
        bytes_fetched: frame.bytes_fetched,
        gpu_bytes: out.stats.resident_bytes,
        cpu_bytes: frame.cpu_bytes,
        rss_mib: crate::bench::rss_mib().0,
        selection_ms: chosen.selection_ms,
        budget_ms: frame.budget.map(|b| b.0),
        predicted_ms: frame.budget.and_then(|b| b.1),
        model_ms: frame.budget.map(|b| b.2),
        candidates: selected.map(|s| s.candidates),
        benefit_bound: selected.map(|s| s.cut.share_of_bound()),
        bound: selected.map(|s| s.cut.bound()),
        morphing: chosen.morphing,
        nodes_touched: chosen.touched,
        clearance_m: frame.clearance_m.0,
        ground_clearance_m: frame.clearance_m.1,
        shadow_steps_mean: mean_or_zero(chosen.steps.iter().map(|&s| f64::from(s))),
        trees: drawn.trees.drawn.trees,
        splats: out.stats.splats as usize,
        splat_fill_px: drawn.trees.drawn.fill_px,
    }
}

/// A frame's trees.
#[derive(Default)]
struct FrameTrees {
    /// Splats, a list per tile.
    splats: Vec<Vec<trees::Splat>>,
    drawn: trees::Drawn,
    /// The cut drawn, with budgets for the groups its selection did not
    /// price (budget mode).
    priced: Option<Selected>,
}

/// The trees near the camera on `tiles`, by screen size or, under a
/// budget, with the splat budgets of the cut drawn.
fn tree_splats(
    options: &FlyOptions,
    tiles: &[Arc<TileData>],
    camera: &Camera,
    blend: &TreeBlend,
    lod: Option<&mut BudgetFlight>,
) -> FrameTrees {
    let mut out = FrameTrees { splats: vec![Vec::new(); tiles.len()], ..FrameTrees::default() };
    let Some(settings) = &options.trees else { return out };
    let refs: Vec<&TileData> = tiles.iter().map(|t| t.as_ref()).collect();
    let groups = trees::groups_near(settings, &refs, camera, blend);
    out.priced = lod.and_then(|lod| lod.price_trees(camera, &refs, &groups));
    let budgets = out.priced.as_ref().map(|s| &s.cut.tree_budgets);
    out.drawn = trees::splats(settings, &groups, budgets, (blend, camera.focal_px()), &mut out.splats);
    out
}

/// The frame's tiles by screen-space error, and what choosing them took.
pub struct Visible {
    /// The tiles, loaded.
    pub tiles: Vec<Arc<TileData>>,
    /// The error threshold that made them fit the GPU cache (once levels
    /// were cut, the largest error of a tile drawn), pixels.
    pub error_px: f64,
    /// Quadtree nodes the selections touched.
    pub touched: usize,
    /// Time of the selections alone (not the loading), ms.
    pub selection_ms: f64,
}

/// The frame's tiles, coarsening the error threshold until they fit the
/// GPU cache (where even the coarsest cut does not, its nearest tiles): by
/// a flight's `sse` selector, or by the stateless walk.
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
            Some(sse) => sse.select(camera, &rule),
            None => quadtree::select(&source.grid(), &source.bounds(), camera, &|id| store.range(id), &rule),
        };
        touched += selection.visited;
        let coarsest = rule.max_error_px > MAX_COARSENED_PX && rule.max_level == 0;
        if selection.tiles.len() <= slots as usize || coarsest {
            let selection_ms = start.elapsed().as_secs_f64() * 1e3;
            // Even the coarsest cut is too many: its nearest tiles, which
            // fill most of the screen, are drawn (a cache of no slot at all
            // is an error: the loading says so).
            let mut chosen = selection.tiles;
            chosen.sort_by(|a, b| a.distance_m.total_cmp(&b.distance_m));
            chosen.truncate((slots as usize).max(1));
            let ids: Vec<_> = chosen.iter().map(|s| s.id).collect();
            // The threshold that made them fit; once levels were cut, the
            // largest error drawn.
            let error_px = match rule.max_level < options.lod.max_level {
                true => chosen.iter().map(|s| s.error_px).fold(options.lod.max_error_px, f64::max),
                false => rule.max_error_px,
            };
            let tiles = store.get_cut(source, &ids)?;
            return Ok(Visible { tiles, error_px, touched, selection_ms });
        }
        // Past any error a screen shows, coarser levels: tiles around a pole
        // that hold the eye in their bounds refine at every error.
        if rule.max_error_px > MAX_COARSENED_PX {
            rule.max_level -= 1;
        } else {
            rule.max_error_px *= 1.25;
        }
    }
}

/// The error threshold, pixels, past which [`visible_tiles`] coarsens by
/// levels.
const MAX_COARSENED_PX: f64 = 1e4;

/// The camera's height above the surface and above the ground of the
/// finest tile held under it, drawn or not (a camera looking ahead often
/// has the ground under it out of view; the coarse tiles over the region
/// are always held). None outside the region.
fn clearance_m(source: &dyn TileSource, store: &TileStore, camera: &Camera) -> (Option<f64>, Option<f64>) {
    let eye = Geodetic::from_ecef(camera.position_ecef);
    match store.finest_at(&source.grid(), eye.lon_deg, eye.lat_deg) {
        Some(under) => (tile::clearance_m(eye, std::slice::from_ref(&under)), tile::ground_clearance_m(eye, &[under])),
        None => (None, None),
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

/// The mean of `values`; 0 (not the −0 an empty sum is) for none.
fn mean_or_zero(values: impl ExactSizeIterator<Item = f64>) -> f64 {
    match values.len() {
        0 => 0.0,
        n => values.sum::<f64>() / n as f64,
    }
}
