//! A frame's tiles, their ray-casting quality and the trees' splats under
//! a frame budget (issue 7, `lod` steps 2 and 4): the candidates become the
//! optimiser's tile forest, shadow quality and tree groups' splat budgets
//! its continuous variables, and its selection the cut the renderer draws.
//!
//! **Costs** are what the renderer spends, as [`CostFeatures`]: one tile
//! (a draw call, its meshes), view rays on the pixels it covers (each at
//! the steps per pixel the renderer measured lately on the tile,
//! [`super::steps`]: rays graze coarse far tiles and plunge into near ones)
//! and shadow rays, pixels × shadow steps × the fetches a step took lately
//! on the tile (a shadow ray stops above the tile's summit; under a fading
//! canopy a step reads the ground too). The model's constants come from
//! measured frame times ([`crate::lod::calibrate`]).
//!
//! **Shadow quality** is continuous: 0 to [`MAX_SHADOW_STEPS`] samples per
//! hit. The optimiser's variables may not depend on which tiles it draws,
//! so a variable is a *shading region* — a candidate at one level `q`, or
//! a candidate leaf above it — and regions partition the view whatever the
//! cut: a drawn tile at or below `q` takes its region's steps, a drawn tile
//! above `q` the mean of the regions it spans weighted by what a step
//! costs on each (which costs what the regions were charged, cost being
//! linear in steps, where its shadow rays fetch per pixel as theirs do).
//! `q` is the deepest level with at most [`MAX_REGIONS`] regions.
//! A region's full-resolution benefit is [`SHADOW_WORTH`] of the benefit of
//! its head's geometry: shadows sharpen what the terrain shows, so they
//! never outweigh refining it (weighed by pixels, full shadows on one
//! coarse tile beat refining the whole view).
//!
//! **Trees** near the camera ([`crate::client::trees`]) come as groups of
//! at most 64, each a continuous variable of up to its trees × splats per
//! tree: worth 000's `k S (N/64) φ(x/capacity)` with `S` its projected
//! pixels (the groups in view sharing the screen: `super::trees_px`;
//! [`TREE_WORTH`] is `k`), costing per splat the splat constant
//! plus the group constant and the fill of its quads spread over the
//! group's capacity. The fill is the group's pixels its splats cover
//! (overlaps counted): a tree's splats cover its crown twice however many
//! it has, so the fill is whole from a splat per tree on, a rising cost
//! that is not convex, nor is a fixed charge; spread, they are. Groups
//! left part-full, which that under-charges, are then trimmed or dropped,
//! fewest splats first, until the cut fits. (Setting the group constant of every group in view aside
//! first let one miscalibrated constant starve the terrain: fifty groups
//! at a fitted 12 ms each left a 640 × 480 flight one tile for good, since
//! frames without trees never corrected it.) Groups the selection did not
//! see, grown on tiles it did not know, get what its cut leaves of the
//! budget ([`price_unseen_trees`]).
//!
//! Invariant: the cut is feasible as [`optimize`] answers it (steps are
//! rounded down, part-full groups trimmed until it fits), and draws at
//! most `max_tiles` tiles (the GPU cache's slots): a larger cut is chosen
//! again under a smaller budget, and where even the coarsest cut is larger,
//! its tiles are merged into their parents, deepest first, until they fit
//! (the view stays whole; its features, benefit and tree budgets are the
//! coarsest cut's).

use super::candidates::Candidate;
use crate::client::trees::TreeBudgets;
use crate::grid::TileId;
use crate::lod::model::{CostFeatures, CostModel, Smooth, group_weight};
use crate::lod::optimizer::{Continuous, Forest, Levels, Node, Selection, Settings, Stop, optimize};
use crate::lod::split::Item;
use std::time::{Duration, Instant};

/// Most shadow samples per hit (the renderer's default is 10).
pub const MAX_SHADOW_STEPS: u32 = 30;
/// Shading regions at most (continuous variables).
pub const MAX_REGIONS: usize = 256;
/// Full shadows on a region are worth this share of what its geometry at
/// full resolution is worth: shadows matter less than shape (a judgement,
/// not a measurement).
pub const SHADOW_WORTH: f64 = 0.3;
/// Halvings of the budget searched when a cut has more tiles than slots
/// (the budget found is within 2⁻¹⁰ of the largest that fits).
const SLOT_BISECTIONS: usize = 10;
/// A tree group's full-resolution benefit per projected pixel at full
/// density (000's `k`): trees are the canopy's near field, worth half the
/// terrain they stand on (a judgement, not a measurement).
pub const TREE_WORTH: f64 = 0.5;

/// What the budget allows.
#[derive(Clone, Copy, Debug)]
pub struct Budget {
    /// Frame budget, ms.
    pub budget_ms: f64,
    /// Tiles at most.
    pub max_tiles: usize,
    /// Whether the sun is on (else shadows cost and give nothing).
    pub shadows: bool,
    /// How long one optimisation may run (the optimiser's own time limit;
    /// it then returns its best feasible answer so far).
    pub time_limit: Option<Duration>,
}

/// A tile to draw and its quality.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Choice {
    /// The tile.
    pub id: TileId,
    /// Shadow samples per hit.
    pub shadow_steps: u32,
    /// Drawn as a morph pair: a selection's refinement of the cut it
    /// replaces (priced as one), or a tile drawn morphing up or down
    /// (measured as one: [`super::steps`]).
    pub morphs: bool,
}

/// A group of trees as the selection sees it: its block on the tree
/// lattice (the key of its budget), the group (centre in ECEF) and the
/// share of the selection's cameras near which it grows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeItem {
    /// Block index.
    pub block: (i64, i64),
    /// Bounding sphere, trees and splats at full resolution.
    pub group: Item,
    /// Share of the cameras the group is drawn from (0–1]: the frames in
    /// the interval the cut is drawn in that draw it, so it is priced and
    /// worth that share of its splats (the cameras ahead are tens of metres
    /// apart in a coarsely sampled flight, the trees' reach not much more;
    /// priced whole, the union of their groups cost half as much again as
    /// any frame drew).
    pub share: f64,
    /// Pixels its splats' quads cover at full resolution: as much at a
    /// splat per tree (a tree's splats cover its crown twice however many
    /// it has), that share below.
    pub fill_px: f64,
}

/// A tree group's splat budget in a cut.
#[derive(Clone, Copy, Debug)]
struct GroupBudget {
    item: TreeItem,
    splats: f64,
}

impl GroupBudget {
    /// What drawing the group costs, times its share: its splats, its
    /// setup, and the fill of its quads, which grows with its splats only
    /// until each tree has one.
    fn features(&self) -> CostFeatures {
        let share = self.item.share;
        let fill_px = self.item.fill_px * (self.splats / self.trees()).min(1.0);
        tree_features(share * self.splats, share, share * fill_px)
    }

    fn trees(&self) -> f64 {
        f64::from(self.item.group.trees.max(1))
    }

    /// What one splat fewer saves, ms: its own cost, and below a splat per
    /// tree its tree's fill.
    fn splat_ms(&self, model: &CostModel) -> f64 {
        let fill_px = if self.splats > self.trees() { 0.0 } else { self.item.fill_px / self.trees() };
        self.item.share * model.marginal_ms(&tree_features(1.0, 0.0, fill_px))
    }
}

/// The chosen cut.
#[derive(Clone, Debug, Default)]
pub struct Cut {
    /// Tiles to draw, none an ancestor of another.
    pub tiles: Vec<Choice>,
    /// Splat budget per tree group priced, by block (0: none drawn; a
    /// group not priced has no entry).
    pub tree_budgets: TreeBudgets,
    /// What drawing them costs, as the model sees it.
    pub features: CostFeatures,
    /// Predicted frame time, ms.
    pub predicted_ms: f64,
    /// Benefit of the cut, and no feasible cut's benefit exceeds the bound.
    pub benefit: f64,
    /// The optimiser's upper bound on the benefit.
    pub upper_bound: f64,
    /// Why the optimiser stopped (`None`: no candidates).
    pub stop: Option<Stop>,
    /// Whether the GPU cache's slots, not the budget, bounded the cut.
    pub slot_bound: bool,
}

impl Cut {
    /// What bounded the cut, as `stats.csv` names it: `budget`, `full`
    /// (nothing left that adds benefit), `limit` (the optimiser's time or
    /// iterations), `slots`, or `none` (no candidates).
    pub fn bound(&self) -> &'static str {
        match (self.slot_bound, self.stop) {
            (true, _) => "slots",
            (false, Some(Stop::Budget)) => "budget",
            (false, Some(Stop::FullResolution)) => "full",
            (false, Some(Stop::Limit)) => "limit",
            (false, None) => "none",
        }
    }

    /// The cut's benefit as a share of the upper bound (1: optimal); 1 when
    /// no cut could have any (nothing in view; a NaN bound stays NaN).
    pub fn share_of_bound(&self) -> f64 {
        match self.upper_bound == 0.0 {
            true => 1.0,
            false => self.benefit / self.upper_bound,
        }
    }
}

/// The features of drawing candidate `c` with `steps` shadow steps.
pub fn features(c: &Candidate, steps: u32) -> CostFeatures {
    let raycast_mpx_steps = c.ray_px * c.view_steps / 1e6;
    CostFeatures {
        tiles: 1.0,
        raycast_mpx_steps,
        faded_mpx_steps: if c.faded { raycast_mpx_steps } else { 0.0 },
        shadow_mpx_steps: c.ray_px * f64::from(steps) * c.shadow_fetches / 1e6,
        ..CostFeatures::default()
    }
}

/// The features of `splats` splats in `groups` groups whose quads cover
/// `fill_px` pixels.
pub fn tree_features(splats: f64, groups: f64, fill_px: f64) -> CostFeatures {
    CostFeatures {
        splats_k: splats / 1e3,
        groups_h: groups / 1e2,
        splat_fill_mpx: fill_px / 1e6,
        ..CostFeatures::default()
    }
}

/// Chooses the cut of `candidates` and the budgets of tree groups `trees`
/// (each with its projected pixels) under `budget` with cost `model`.
pub fn choose(candidates: &[Candidate], trees: &[(TreeItem, f64)], model: &CostModel, budget: &Budget) -> Cut {
    let nodes: Vec<Node> = candidates
        .iter()
        .map(|c| Node { parent: c.parent, benefit: c.benefit, cost_ms: model.marginal_ms(&features(c, 0)) })
        .collect();
    let Ok(forest) = Forest::new(nodes) else { return Cut::default() };
    if forest.is_empty() {
        return Cut::default();
    }
    let regions = Regions::new(candidates, &forest, budget.shadows);
    let mut continuous = regions.variables(candidates, model);
    continuous.extend(trees.iter().map(|(t, px)| tree_variable(t, *px, model)));
    let run = |budget_ms: f64| {
        let deadline = budget.time_limit.map(|t| Instant::now() + t);
        let selection = optimize(&forest, &continuous, &Settings { deadline, ..Settings::budget(budget_ms) });
        let drawn: Vec<u32> = selection.drawn(&forest).collect();
        (selection, drawn)
    };
    let max_tiles = budget.max_tiles.max(1);
    let ((selection, drawn), slot_bound) = within_slots(run, budget.budget_ms - model.constants_ms[0], max_tiles);
    let tiles: Vec<Choice> = drawn
        .iter()
        .map(|&i| Choice {
            id: candidates[i as usize].id,
            shadow_steps: regions.steps(i, &forest, candidates, &selection.resolutions),
            morphs: candidates[i as usize].morphs,
        })
        .collect();
    let groups = group_budgets(trees, &selection.resolutions[regions.heads.len().min(selection.resolutions.len())..]);
    let terrain = drawn
        .iter()
        .zip(&tiles)
        .map(|(&i, t)| features(&candidates[i as usize], t.shadow_steps))
        .fold(CostFeatures::default(), |a, f| a.plus(&f));
    // Even the coarsest cut may need more slots (a wide view of many root
    // tiles, or the tiles around a pole, refined there to show samples no
    // larger than the floor): coarser tiles, whole.
    let tiles = coarsened(tiles, max_tiles);
    let (features, groups) = fit_groups(terrain, groups, model, budget.budget_ms);
    let mut tree_budgets = TreeBudgets::new();
    record_budgets(&mut tree_budgets, trees, groups);
    Cut {
        predicted_ms: model.predict_ms(&features),
        features,
        tiles,
        tree_budgets,
        benefit: selection.benefit,
        upper_bound: selection.upper_bound,
        stop: Some(selection.stop),
        slot_bound,
    }
}

/// The optimiser's selection by `run` under `budget_ms` and the tiles it
/// draws; where they are more than `max_tiles`, those of the largest
/// budget whose cut fits, by bisection (and `true`: the slots bound it).
fn within_slots(
    run: impl Fn(f64) -> (Selection, Vec<u32>),
    budget_ms: f64,
    max_tiles: usize,
) -> ((Selection, Vec<u32>), bool) {
    let first = run(budget_ms);
    if first.1.len() <= max_tiles {
        return (first, false);
    }
    let (mut lo, mut hi) = (0.0, first.0.cost_ms);
    let mut fits = run(lo);
    for _ in 0..SLOT_BISECTIONS {
        let mid = 0.5 * (lo + hi);
        let cut = run(mid);
        if cut.1.len() <= max_tiles {
            (lo, fits) = (mid, cut);
        } else {
            hi = mid;
        }
    }
    (fits, true)
}

/// Gives tree groups the cut's selection did not price, `unseen` (each
/// with its projected pixels), splat budgets from what `budget_ms` leaves
/// after the cut: its selection grew its groups on the tiles drawn before
/// it, so it saw none before the first frame and few after a jump. They
/// take one slope level, as the optimiser sets continuous variables, and
/// are trimmed until the cut fits, as its own groups are; the cut's
/// features and prediction include them. A budget spent leaves them none.
pub fn price_unseen_trees(cut: &mut Cut, unseen: &[(TreeItem, f64)], model: &CostModel, budget_ms: f64) {
    let left_ms = budget_ms - model.predict_ms(&cut.features);
    let variables: Vec<Continuous> = unseen.iter().map(|(t, px)| tree_variable(t, *px, model)).collect();
    let levels = Levels::new(&variables, Smooth::default());
    let splats = levels.resolutions(levels.level_for_budget(left_ms));
    let (features, groups) = fit_groups(cut.features, group_budgets(unseen, &splats), model, budget_ms);
    record_budgets(&mut cut.tree_budgets, unseen, groups);
    (cut.features, cut.predicted_ms) = (features, model.predict_ms(&features));
}

/// The groups of `trees` given at least a splat by `splats` (in order).
fn group_budgets(trees: &[(TreeItem, f64)], splats: &[f64]) -> Vec<GroupBudget> {
    trees
        .iter()
        .zip(splats)
        .filter(|(_, x)| **x >= 1.0)
        .map(|((item, _), x)| GroupBudget { item: *item, splats: x.floor() })
        .collect()
}

/// Records the groups `priced`: those `kept` with their splats, the rest
/// with none.
fn record_budgets(budgets: &mut TreeBudgets, priced: &[(TreeItem, f64)], kept: Vec<GroupBudget>) {
    budgets.extend(priced.iter().map(|(t, _)| (t.block, 0.0)));
    budgets.extend(kept.into_iter().map(|g| (g.item.block, g.splats)));
}

/// `tiles` merged into their parents, deepest level first (each parent with
/// its children's most shadow steps), until at most `max_tiles` remain;
/// past level 0, the first `max_tiles`.
fn coarsened(mut tiles: Vec<Choice>, max_tiles: usize) -> Vec<Choice> {
    while tiles.len() > max_tiles {
        let deepest = tiles.iter().map(|c| c.id.level).max().unwrap_or(0);
        if deepest == 0 {
            tiles.truncate(max_tiles);
            break;
        }
        let mut merged: Vec<Choice> = Vec::new();
        for c in tiles {
            let id = if c.id.level == deepest { c.id.parent().unwrap_or(c.id) } else { c.id };
            match merged.iter_mut().find(|m| m.id == id) {
                Some(m) => m.shadow_steps = m.shadow_steps.max(c.shadow_steps),
                None => merged.push(Choice { id, ..c }),
            }
        }
        tiles = merged;
    }
    tiles
}

/// The features of the cut `terrain` plus `groups`, trimmed or dropped,
/// fewest splats first, until it fits `budget_ms`; the groups kept.
fn fit_groups(
    terrain: CostFeatures,
    mut groups: Vec<GroupBudget>,
    model: &CostModel,
    budget_ms: f64,
) -> (CostFeatures, Vec<GroupBudget>) {
    let with_trees = |groups: &[GroupBudget]| groups.iter().fold(terrain, |a, g| a.plus(&g.features()));
    // Fewest splats last: the loop trims that group, or drops it.
    groups.sort_by(|a, b| b.splats.total_cmp(&a.splats));
    loop {
        let over_ms = model.predict_ms(&with_trees(&groups)) - budget_ms;
        let Some(last) = groups.last_mut().filter(|_| over_ms > 0.0) else { break };
        // Down to a splat per tree first: below that each splat saves fill.
        let above = last.splats - last.trees();
        let mut trim = (over_ms / last.splat_ms(model)).ceil();
        if above > 0.0 {
            trim = trim.min(above);
        }
        if last.splats - trim >= 1.0 {
            last.splats -= trim;
        } else {
            groups.pop();
        }
    }
    (with_trees(&groups), groups)
}

/// A tree group's variable: its worth and its cost per splat, the group
/// constant and the full fill spread over its capacity (the chord of a
/// cost that rises steeply to a splat per tree), both times its share of
/// the cameras.
fn tree_variable(t: &TreeItem, px: f64, model: &CostModel) -> Continuous {
    let capacity = t.group.capacity.max(0.0);
    let fixed_ms = model.marginal_ms(&tree_features(0.0, 1.0, t.fill_px));
    Continuous {
        weight: t.share * group_weight(px, t.group.trees, TREE_WORTH),
        capacity,
        cost_per_unit_ms: t.share * (model.marginal_ms(&tree_features(1.0, 0.0, 0.0)) + fixed_ms / capacity.max(1.0)),
    }
}

/// The shading regions: per candidate, its region (a variable index), if
/// it lies in one; the candidate heading each region.
struct Regions {
    of: Vec<Option<u32>>,
    heads: Vec<u32>,
}

impl Regions {
    fn new(candidates: &[Candidate], forest: &Forest, shadows: bool) -> Regions {
        let mut regions = Regions { of: vec![None; candidates.len()], heads: Vec::new() };
        if !shadows {
            return regions;
        }
        let q = region_level(candidates, forest);
        for (i, c) in candidates.iter().enumerate() {
            let inherited = c.parent.and_then(|p| regions.of[p as usize]);
            let heads = c.id.level == q || (c.id.level < q && forest.children(i as u32).is_empty());
            regions.of[i] = match (inherited, heads) {
                (Some(r), _) => Some(r),
                (None, true) => {
                    regions.heads.push(i as u32);
                    Some(regions.heads.len() as u32 - 1)
                }
                (None, false) => None,
            };
        }
        regions
    }

    /// A variable per region: its geometry's worth and its pixels' cost
    /// per step.
    fn variables(&self, candidates: &[Candidate], model: &CostModel) -> Vec<Continuous> {
        let per_step = CostFeatures { shadow_mpx_steps: 1e-6, ..CostFeatures::default() };
        let ms_per_px_step = model.marginal_ms(&per_step);
        self.heads
            .iter()
            .map(|&h| {
                let c = &candidates[h as usize];
                let casts = c.ray_px > 0.0;
                Continuous {
                    weight: if casts { SHADOW_WORTH * c.benefit } else { 0.0 },
                    capacity: f64::from(MAX_SHADOW_STEPS),
                    cost_per_unit_ms: ms_per_px_step * c.ray_px * c.shadow_fetches,
                }
            })
            .collect()
    }

    /// Shadow steps of drawn node `i`.
    fn steps(&self, i: u32, forest: &Forest, candidates: &[Candidate], x: &[f64]) -> u32 {
        let at = |r: u32| x.get(r as usize).copied().unwrap_or(0.0);
        if let Some(r) = self.of[i as usize] {
            return at(r).floor().clamp(0.0, f64::from(MAX_SHADOW_STEPS)) as u32;
        }
        // Above the region level: the mean of the regions below, weighted
        // by what a step costs on each.
        let (mut sum, mut px) = (0.0, 0.0);
        let mut stack = vec![i];
        while let Some(v) = stack.pop() {
            match self.of[v as usize] {
                Some(r) => {
                    let c = &candidates[v as usize];
                    let w = c.ray_px * c.shadow_fetches;
                    sum += w * at(r);
                    px += w;
                }
                None => stack.extend(forest.children(v)),
            }
        }
        if px > 0.0 { (sum / px).floor().clamp(0.0, f64::from(MAX_SHADOW_STEPS)) as u32 } else { 0 }
    }
}

/// The deepest level at which the candidates of that level and the leaves
/// above it are at most [`MAX_REGIONS`].
fn region_level(candidates: &[Candidate], forest: &Forest) -> u32 {
    let deepest = candidates.iter().map(|c| c.id.level).max().unwrap_or(0);
    let mut at = vec![0usize; deepest as usize + 2];
    let mut leaves = vec![0usize; deepest as usize + 2];
    for (i, c) in candidates.iter().enumerate() {
        at[c.id.level as usize] += 1;
        if forest.children(i as u32).is_empty() {
            leaves[c.id.level as usize] += 1;
        }
    }
    let mut above = 0;
    let mut best = 0;
    for level in 0..=deepest {
        if at[level as usize] + above <= MAX_REGIONS {
            best = level;
        }
        above += leaves[level as usize];
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::camera::Camera;
    use crate::client::globe::Geodetic;
    use crate::client::lod::candidates::{candidates, demo_scope};
    use crate::client::lod::steps::{RaySteps, VIEW_STEPS};
    use glam::DVec3;

    fn demo_candidates() -> Vec<Candidate> {
        let cameras = [Camera::looking(Geodetic::new(10.1, 46.32, 2500.0), 10.0, -15.0, 60.0, (320, 240))];
        let steps = RaySteps::new(VIEW_STEPS);
        let scope = demo_scope(&cameras, &|_| Some((500.0, 3500.0)), &steps);
        candidates(&scope).tiles
    }

    const MODEL: CostModel = CostModel { constants_ms: [1.0, 0.05, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0] };

    fn budget(ms: f64, shadows: bool) -> Budget {
        Budget { budget_ms: ms, max_tiles: 256, shadows, time_limit: None }
    }

    #[test]
    fn cuts_fit_their_budget_and_more_budget_buys_more() {
        let c = demo_candidates();
        let mut last = 0.0;
        for ms in [3.0, 6.0, 12.0, 24.0] {
            let cut = choose(&c, &[], &MODEL, &budget(ms, true));
            assert!(cut.predicted_ms <= ms + 1e-9, "{ms}: {}", cut.predicted_ms);
            assert!(cut.benefit >= last && cut.benefit <= cut.upper_bound * (1.0 + 1e-9));
            last = cut.benefit;
            // A cut: no drawn tile is an ancestor of another.
            for a in &cut.tiles {
                assert!(!cut.tiles.iter().any(|b| b.id != a.id && b.id.level > a.id.level && {
                    let up = b.id.level - a.id.level;
                    (b.id.row >> up, b.id.col >> up) == (a.id.row, a.id.col)
                }));
            }
        }
        let rich = choose(&c, &[], &MODEL, &budget(1e4, true));
        assert_eq!(rich.stop, Some(Stop::FullResolution));
        let f = rich.features;
        let full = f64::from(MAX_SHADOW_STEPS) * f.raycast_mpx_steps / VIEW_STEPS;
        assert!(f.shadow_mpx_steps > 0.95 * full && f.shadow_mpx_steps <= full * (1.0 + 1e-9), "{f:?}");
        assert!(rich.tiles.len() > choose(&c, &[], &MODEL, &budget(3.0, true)).tiles.len());
    }

    #[test]
    fn a_time_limit_stops_each_selection_with_a_cut_that_fits() {
        let c = demo_candidates();
        let limited = Budget { time_limit: Some(Duration::ZERO), ..budget(12.0, true) };
        let cut = choose(&c, &[], &MODEL, &limited);
        assert_eq!(cut.stop, Some(Stop::Limit));
        assert!(!cut.tiles.is_empty() && cut.predicted_ms <= 12.0 + 1e-9, "{}", cut.predicted_ms);
        assert_ne!(choose(&c, &[], &MODEL, &budget(12.0, true)).stop, Some(Stop::Limit));
    }

    #[test]
    fn a_cut_with_nothing_to_gain_reaches_its_bound() {
        assert_eq!(Cut::default().share_of_bound(), 1.0, "no candidate in view: no NaN");
        let half = Cut { benefit: 1.0, upper_bound: 2.0, ..Cut::default() };
        assert_eq!(half.share_of_bound(), 0.5);
    }

    #[test]
    fn more_steps_per_pixel_buy_fewer_tiles_within_the_budget() {
        let c = demo_candidates();
        // A budget that binds: rays cost what the steps say, tiles the rest
        // (above the coarsest cut at 40 steps, below everything at 10).
        let at = |view_steps: f64| {
            let priced: Vec<Candidate> = c.iter().map(|t| Candidate { view_steps, ..*t }).collect();
            choose(&priced, &[], &MODEL, &budget(2.3, false))
        };
        let (cheap, dear) = (at(10.0), at(40.0));
        for cut in [&cheap, &dear] {
            assert!(cut.predicted_ms <= 2.3 + 1e-9 && cut.stop == Some(Stop::Budget), "{cut:?}");
        }
        assert!(dear.tiles.len() < cheap.tiles.len(), "{} vs {}", dear.tiles.len(), cheap.tiles.len());
        assert!(dear.benefit < cheap.benefit);
    }

    #[test]
    fn shadow_steps_that_fetch_more_buy_fewer_steps_within_the_budget() {
        let c = demo_candidates();
        // A budget that buys everything at 0.5 fetches per shadow step,
        // not at 2.
        let at = |shadow_fetches: f64| {
            let priced: Vec<Candidate> = c.iter().map(|t| Candidate { shadow_fetches, ..*t }).collect();
            choose(&priced, &[], &MODEL, &budget(4.0, true))
        };
        let (light, heavy) = (at(0.5), at(2.0));
        let steps = |cut: &Cut| cut.tiles.iter().map(|t| f64::from(t.shadow_steps)).sum::<f64>();
        assert_eq!((light.stop, heavy.stop), (Some(Stop::FullResolution), Some(Stop::Budget)));
        assert!(heavy.predicted_ms <= 4.0 + 1e-9, "{heavy:?}");
        assert!(steps(&heavy) < steps(&light), "{} vs {}", steps(&heavy), steps(&light));
        // Priced as drawn: ray-cast pixels × steps × fetches per step.
        let priced = |cut: &Cut, fetches: f64| -> f64 {
            let px = |id| c.iter().find(|t| t.id == id).map_or(0.0, |t| t.ray_px);
            cut.tiles.iter().map(|t| px(t.id) * f64::from(t.shadow_steps) * fetches / 1e6).sum()
        };
        for (cut, fetches) in [(&light, 0.5), (&heavy, 2.0)] {
            let expected = priced(cut, fetches);
            assert!(expected > 0.0 && (cut.features.shadow_mpx_steps / expected - 1.0).abs() < 1e-9, "{expected}");
        }
    }

    #[test]
    fn tiles_under_a_fading_canopy_pay_its_pipelines_surcharge() {
        let c = demo_candidates();
        let model = CostModel { constants_ms: [1.0, 0.05, 0.5, 0.5, 0.0, 0.0, 0.0, 0.5] };
        let at = |faded: bool| {
            let priced: Vec<Candidate> = c.iter().map(|t| Candidate { faded, ..*t }).collect();
            choose(&priced, &[], &model, &budget(2.5, false))
        };
        let (whole, fading) = (at(false), at(true));
        assert_eq!(whole.features.faded_mpx_steps, 0.0);
        assert!(fading.features.faded_mpx_steps > 0.0);
        assert_eq!(fading.features.faded_mpx_steps, fading.features.raycast_mpx_steps);
        for cut in [&whole, &fading] {
            assert!(cut.predicted_ms <= 2.5 + 1e-9 && cut.stop == Some(Stop::Budget), "{cut:?}");
        }
        assert!(fading.tiles.len() < whole.tiles.len(), "{} vs {}", fading.tiles.len(), whole.tiles.len());
    }

    #[test]
    fn no_sun_no_shadow_steps_and_slots_bound_the_cut() {
        let c = demo_candidates();
        let dark = choose(&c, &[], &MODEL, &budget(50.0, false));
        assert!(dark.tiles.iter().all(|t| t.shadow_steps == 0) && dark.features.shadow_mpx_steps == 0.0);
        let few = choose(&c, &[], &MODEL, &Budget { max_tiles: 8, ..budget(1e4, true) });
        assert!(few.tiles.len() <= 8 && !few.tiles.is_empty(), "{}", few.tiles.len());
        assert_eq!((few.bound(), dark.bound()), ("slots", "full"));
        // Fewer slots than the coarsest cut's tiles: coarser tiles, the
        // view whole (each of the cut's tiles lies in one of them).
        let coarsest = choose(&c, &[], &MODEL, &budget(0.0, true)).tiles;
        assert!(coarsest.len() > 1, "{} tiles in the coarsest cut", coarsest.len());
        let one = choose(&c, &[], &MODEL, &Budget { max_tiles: 1, ..budget(1e4, true) });
        assert_eq!(one.tiles.len(), 1, "{:?}", one.tiles);
        let within =
            |id: TileId| std::iter::successors(Some(id), |t| t.parent()).any(|a| one.tiles.iter().any(|t| t.id == a));
        assert!(coarsest.iter().all(|t| within(t.id)), "{:?} covers {coarsest:?}", one.tiles);
    }

    #[test]
    fn a_group_near_some_of_the_cameras_is_priced_at_that_share() {
        let c = demo_candidates();
        let model = CostModel { constants_ms: [1.0, 0.05, 0.5, 0.5, 2.0, 0.01, 0.0, 0.0] };
        let group = Item { center_m: DVec3::ZERO, radius_m: 30.0, trees: 64, capacity: 64.0 * 24.0 };
        let cut = |share: f64| {
            let trees = [(TreeItem { block: (0, 0), group, share, fill_px: 0.0 }, 20_000.0)];
            choose(&c, &trees, &model, &budget(1e3, true))
        };
        let (all, third) = (cut(1.0), cut(1.0 / 3.0));
        // Room for every splat either way: the same budget, a third the cost.
        assert_eq!(all.tree_budgets, third.tree_budgets);
        assert_eq!(all.tree_budgets[&(0, 0)], 64.0 * 24.0);
        assert!((third.features.splats_k * 3.0 - all.features.splats_k).abs() < 1e-9, "{:?}", third.features);
        assert!((third.features.groups_h * 3.0 - all.features.groups_h).abs() < 1e-12);
    }

    /// A model under which a full group costs 3.1 ms (the groups compete
    /// with the terrain), and three groups of 64 trees seen at 20,000,
    /// 2,000 and 0 pixels.
    fn three_groups() -> (CostModel, [(TreeItem, f64); 3]) {
        let model = CostModel { constants_ms: [1.0, 0.05, 0.5, 0.5, 2.0, 0.01, 0.0, 0.0] };
        let group = Item { center_m: DVec3::ZERO, radius_m: 30.0, trees: 64, capacity: 64.0 * 24.0 };
        let item = |k: i64| TreeItem { block: (k, 0), group, share: 1.0, fill_px: 0.0 };
        (model, [(item(0), 20_000.0), (item(1), 2_000.0), (item(2), 0.0)])
    }

    #[test]
    fn tree_groups_get_splats_by_their_worth_within_the_budget() {
        let c = demo_candidates();
        let (model, trees) = three_groups();
        let cut = choose(&c, &trees, &model, &budget(8.0, true));
        let got = |k: i64| cut.tree_budgets.get(&(k, 0)).copied().unwrap_or(0.0);
        assert!(got(0) > got(1) && got(1) > 0.0 && got(1) < 64.0 * 24.0, "{:?}", cut.tree_budgets);
        assert_eq!(got(2), 0.0, "a group out of view gets nothing");
        assert!(cut.predicted_ms <= 8.0 + 1e-9, "{}", cut.predicted_ms);
        assert!((cut.features.splats_k - (got(0) + got(1)) / 1e3).abs() < 1e-12);
        // The terrain is whole at 3.8 ms; the splats take the rest.
        let terrain = model.predict_ms(&CostFeatures { splats_k: 0.0, groups_h: 0.0, ..cut.features });
        let bare = choose(&c, &[], &model, &budget(8.0, true));
        assert_eq!((bare.stop, bare.bound()), (Some(Stop::FullResolution), "full"));
        assert!((terrain - bare.predicted_ms).abs() < 1e-9 && cut.predicted_ms > 7.9, "{terrain} {}", cut.predicted_ms);
        // With less, the terrain gives way too.
        let tight = choose(&c, &trees, &model, &budget(4.0, true));
        assert!(tight.predicted_ms <= 4.0 + 1e-9 && !tight.tree_budgets.is_empty());
        let rich = choose(&c, &trees, &model, &budget(1e4, true));
        assert_eq!(rich.tree_budgets.get(&(0, 0)), Some(&(64.0 * 24.0)));
    }

    #[test]
    fn groups_the_selection_did_not_see_take_what_its_budget_leaves() {
        let c = demo_candidates();
        let (model, trees) = three_groups();
        // The terrain is whole at 3.8 ms: the unseen groups get the rest,
        // by worth, as the selection would have given them.
        let mut cut = choose(&c, &[], &model, &budget(8.0, true));
        let terrain = cut.clone();
        price_unseen_trees(&mut cut, &trees, &model, 8.0);
        let got = |k: i64| cut.tree_budgets[&(k, 0)];
        assert!(got(0) > got(1) && got(1) > 0.0 && got(2) == 0.0, "{:?}", cut.tree_budgets);
        assert!(cut.predicted_ms <= 8.0 + 1e-9 && cut.predicted_ms > 7.9, "{}", cut.predicted_ms);
        assert!((cut.features.splats_k - (got(0) + got(1)) / 1e3).abs() < 1e-12);
        assert_eq!(cut.tiles, terrain.tiles);
        // A budget spent on the terrain leaves them none, priced at none.
        let mut spent = choose(&c, &[], &model, &budget(3.0, true));
        let before = spent.predicted_ms;
        price_unseen_trees(&mut spent, &trees, &model, 3.0);
        assert!(spent.tree_budgets.values().all(|&b| b == 0.0) && spent.tree_budgets.len() == 3);
        assert_eq!(spent.predicted_ms, before);
    }

    #[test]
    fn a_groups_fill_is_paid_from_its_first_splats_and_trimmed_below_a_splat_per_tree() {
        let c = demo_candidates();
        // Splats free, fill 1 ms per 10,000 pixels: the group's 64 trees
        // cover 100,000 pixels from a splat each to 24 each.
        let model = CostModel { constants_ms: [1.0, 0.05, 0.5, 0.5, 0.0, 0.0, 100.0, 0.0] };
        let group = Item { center_m: DVec3::ZERO, radius_m: 30.0, trees: 64, capacity: 64.0 * 24.0 };
        let trees = [(TreeItem { block: (0, 0), group, share: 1.0, fill_px: 1e5 }, 20_000.0)];
        let bare = choose(&c, &[], &model, &budget(1e4, true));
        let whole = choose(&c, &trees, &model, &budget(bare.predicted_ms + 11.0, true));
        assert_eq!(whole.tree_budgets[&(0, 0)], 64.0 * 24.0);
        assert!((whole.features.splat_fill_mpx - 0.1).abs() < 1e-12, "{:?}", whole.features);
        // 4 ms for trees: fewer than a tree's worth of splats each, on as
        // many trees, the fill their share.
        let part = choose(&c, &trees, &model, &budget(bare.predicted_ms + 4.0, true));
        let splats = part.tree_budgets[&(0, 0)];
        assert!(splats < 64.0 && part.predicted_ms <= bare.predicted_ms + 4.0 + 1e-9, "{splats} {}", part.predicted_ms);
        assert!((part.features.splat_fill_mpx - 0.1 * splats / 64.0).abs() < 1e-12, "{:?}", part.features);
        assert_eq!(part.tiles.len(), bare.tiles.len(), "the terrain stays whole");
    }

    #[test]
    fn a_costly_group_constant_does_not_starve_the_terrain() {
        // Fifty groups in view at 12 ms each (a fit gone wrong): the
        // terrain still gets what the budget allows, and the cut fits.
        let c = demo_candidates();
        let model = CostModel { constants_ms: [1.0, 0.05, 0.5, 0.5, 2.0, 1200.0, 0.0, 0.0] };
        let group = Item { center_m: DVec3::ZERO, radius_m: 30.0, trees: 64, capacity: 64.0 * 24.0 };
        let trees: Vec<_> =
            (0..50).map(|k| (TreeItem { block: (k, 0), group, share: 1.0, fill_px: 0.0 }, 2_000.0)).collect();
        let cut = choose(&c, &trees, &model, &budget(8.0, true));
        let bare = choose(&c, &[], &model, &budget(8.0, true));
        assert!(cut.predicted_ms <= 8.0 + 1e-9, "{}", cut.predicted_ms);
        assert_eq!(cut.tiles.len(), bare.tiles.len(), "{:?}", cut.tree_budgets);
        // Affordable, a group gets its splats with the constant paid once.
        let cheap = CostModel { constants_ms: [1.0, 0.05, 0.5, 0.5, 2.0, 100.0, 0.0, 0.0] };
        let rich = choose(&c, &trees, &cheap, &budget(1e4, true));
        assert_eq!(rich.tree_budgets.len(), 50);
        assert!((rich.features.groups_h - 0.5).abs() < 1e-12 && rich.predicted_ms <= 1e4);
    }

    #[test]
    fn odd_input_gives_an_empty_or_coarsest_cut() {
        assert!(choose(&[], &[], &MODEL, &budget(10.0, true)).tiles.is_empty());
        let c = demo_candidates();
        for ms in [0.0, -5.0, f64::NAN] {
            let cut = choose(&c, &[], &MODEL, &budget(ms, true));
            let roots = c.iter().filter(|t| t.parent.is_none()).count();
            assert_eq!(cut.tiles.len(), roots, "{ms}");
            assert!(cut.predicted_ms.is_finite());
        }
    }
}
