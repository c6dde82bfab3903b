//! The client's LOD selection under a frame budget (issue 7): what the
//! pure [`crate::lod`] library is fed with, and what comes back to draw.
//! `sylva fly --lod budget` uses it; `--lod sse` keeps the screen-space
//! error rule of [`super::sse`].
//!
//! - [`coverage`]: the pixels a tile covers, and at what sample density.
//! - [`candidates`]: the culled quadtree with each tile's benefit and cost
//!   in pixels, for one camera or several predicted ones.
//! - [`budget`]: the optimiser's forest, its shadow-quality and tree-group
//!   variables, and the cut it selects.
//! - [`steps`]: the view-ray steps per pixel measured per tile, which
//!   price the candidates' rays.
//! - [`ahead`]: the predicted cameras and the conservative cone a
//!   selection is for.
//! - [`worker`]: the selection thread.
//! - [`morphs`]: geomorphs of refined tiles from the coarser tile drawn
//!   before.
//! - [`flight`]: a flight's selections, amortised over frames on the
//!   selection thread, and the cost model calibrated from its measured
//!   frame times.
//!
//! No wgpu and no I/O: the renderer and the flight own the GPU and tiles.

pub mod ahead;
pub mod budget;
pub mod candidates;
pub mod coverage;
pub mod flight;
pub mod morphs;
pub mod steps;
pub mod worker;

use super::camera::Camera;
use super::store::Knowledge;
use super::trees::TreeSettings;
use crate::grid::{BBox, TileGrid, TileId};
use crate::lod::model::{CostFeatures, CostModel};
use crate::lod::predict::Cone;
use budget::{Budget, Choice, Cut, TreeItem};
use candidates::{Candidate, Scope};
use std::collections::HashSet;
use std::time::Instant;
use steps::RaySteps;

/// Candidates looked at, at most: far more than a frame draws (the GPU
/// cache holds at most 256 tiles), few enough to select in milliseconds.
pub const MAX_CANDIDATES: usize = 16_384;

/// The fixed inputs of every selection of a flight.
#[derive(Clone, Debug)]
pub struct Selector {
    /// The tile grid.
    pub grid: TileGrid,
    /// The region's bounds.
    pub bounds: BBox,
    /// What is known of loaded tiles.
    pub knowledge: Knowledge,
    /// The canopy fade: reference height (m), low and high (px).
    pub fade: (f64, f64, f64),
    /// Trees drawn as splats near the camera, if any (their blend fades
    /// the canopy there).
    pub trees: Option<TreeSettings>,
    /// Deepest level.
    pub max_level: u32,
}

/// A selection and what it took.
#[derive(Clone, Debug, Default)]
pub struct Selected {
    /// The cut.
    pub cut: Cut,
    /// Candidate tiles.
    pub candidates: usize,
    /// Wall-clock ms of the selection (candidates and optimiser).
    pub ms: f64,
}

impl Selector {
    /// The lowest ground known at `(lon, lat)`, degrees: that of the finest
    /// loaded tile there.
    pub fn lowest_ground_m(&self, lon: f64, lat: f64) -> Option<f64> {
        let deepest = self.grid.tile_containing(lon, lat, self.max_level);
        self.knowledge.range(deepest).map(|(lo, _)| lo)
    }

    /// The cut for `cameras` (the cone, if any, widens culling) and the
    /// splat budgets of tree groups `trees` under `budget` with cost
    /// `model`, tiles' rays priced at `steps`, those refining the cut
    /// `refining` (under geomorphing) as morph pairs.
    pub fn select(
        &self,
        cameras: &[Camera],
        cone: Option<Cone>,
        trees: &[TreeItem],
        (model, budget): (&CostModel, &Budget),
        (steps, refining): (&RaySteps, Option<&HashSet<TileId>>),
    ) -> Selected {
        let start = Instant::now();
        let found = self.with_scope(cameras, cone, (steps, refining), candidates::candidates);
        let cut = cut_for(cameras, &found.tiles, trees, (model, budget));
        Selected { cut, candidates: found.tiles.len(), ms: start.elapsed().as_secs_f64() * 1e3 }
    }

    /// What drawing `drawn` from `camera` costs with tiles' rays priced at
    /// `steps`, measured as a selection measures its candidates (so
    /// calibrated constants fit predictions).
    pub fn features(&self, camera: &Camera, drawn: &[Choice], steps: &RaySteps) -> CostFeatures {
        self.with_scope(std::slice::from_ref(camera), None, (steps, None), |scope| {
            let tiles: Vec<_> = drawn.iter().map(|c| (c.id, c.morphs)).collect();
            candidates::drawn(scope, &tiles)
                .iter()
                .zip(drawn)
                .map(|(t, c)| budget::features(t, c.shadow_steps))
                .fold(CostFeatures::default(), |a, f| a.plus(&f))
        })
    }

    fn with_scope<R>(
        &self,
        cameras: &[Camera],
        cone: Option<Cone>,
        (steps, refining): (&RaySteps, Option<&HashSet<TileId>>),
        f: impl FnOnce(&Scope) -> R,
    ) -> R {
        let known = |id| self.knowledge.get(id);
        let range = |id| self.knowledge.range(id);
        f(&Scope {
            grid: self.grid,
            bounds: self.bounds,
            cameras,
            cone,
            fade: self.fade,
            trees: self.trees,
            known: &known,
            range: &range,
            max_level: self.max_level,
            limit: MAX_CANDIDATES,
            steps,
            refining,
        })
    }
}

/// The cut of `tiles` and the splat budgets of the tree groups `trees`,
/// seen from `cameras` ([`trees_px`]), under `budget` with cost `model`.
fn cut_for(cameras: &[Camera], tiles: &[Candidate], trees: &[TreeItem], (model, budget): (&CostModel, &Budget)) -> Cut {
    let seen: Vec<(TreeItem, f64)> = trees.iter().copied().zip(trees_px(cameras, trees)).collect();
    budget::choose(tiles, &seen, model, budget)
}

/// Pixels each of the tree groups `trees` covers, from the best placed of
/// `cameras`: from each, its bounding sphere's projected disc (none outside
/// the view), the discs of all the groups together at most the screen —
/// scaled down alike where they sum to more. The groups' trees stand
/// apart, so together they cover at most the screen; their discs overlap:
/// near a low camera each is the screen's size, and a dozen groups around
/// it, worth a dozen screens, outweighed the whole terrain and dropped the
/// cut to its coarsest tiles (`demo_dive` at 160 × 128, 100 ms).
fn trees_px(cameras: &[Camera], trees: &[TreeItem]) -> Vec<f64> {
    let mut px = vec![0.0f64; trees.len()];
    for c in cameras {
        let screen = f64::from(c.width_px) * f64::from(c.height_px);
        let discs: Vec<f64> = trees.iter().map(|t| disc_px(c, t).min(screen)).collect();
        let total: f64 = discs.iter().sum();
        let scale = if total > screen { screen / total } else { 1.0 };
        for (p, d) in px.iter_mut().zip(discs) {
            *p = p.max(d * scale);
        }
    }
    px
}

/// The projected disc of tree group `t`'s bounding sphere from `c`,
/// pixels (not bounded by the screen); 0 outside the view.
fn disc_px(c: &Camera, t: &TreeItem) -> f64 {
    if !c.side_planes().iter().all(|n| n.dot(t.group.center_m - c.position_ecef) >= -t.group.radius_m) {
        return 0.0;
    }
    let d = (t.group.center_m.distance(c.position_ecef) - t.group.radius_m).max(1.0);
    let r_px = t.group.radius_m * c.focal_px() / d;
    std::f64::consts::PI * r_px * r_px
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::globe::Geodetic;
    use crate::client::lod::steps::VIEW_STEPS;
    use crate::lod::split::Item;

    /// 60 m above the forest at the end of `demo_dive.toml`, 160 × 128.
    fn low_camera() -> Camera {
        Camera::looking(Geodetic::new(10.133, 46.3595, 1110.0), 120.0, -30.0, 60.0, (160, 128))
    }

    /// `rows × cols` groups of 40 trees, spheres of 45 m, 80 to 170 m
    /// along the view of `camera`.
    fn groups_ahead(camera: &Camera, rows: usize, cols: usize) -> Vec<TreeItem> {
        let right = camera.rotation.col(0);
        let mut items = Vec::new();
        for r in 0..rows {
            for k in 0..cols {
                let d = 80.0 + 30.0 * r as f64;
                let x = (k as f64 - (cols as f64 - 1.0) / 2.0) * 0.5 * d / cols as f64;
                let center_m = camera.position_ecef + camera.forward() * d + right * x;
                let group = Item { center_m, radius_m: 45.0, trees: 40, capacity: 960.0 };
                items.push(TreeItem { block: (r as i64, k as i64), group, share: 1.0, fill_px: 0.0 });
            }
        }
        items
    }

    #[test]
    fn tree_groups_share_the_screen() {
        let camera = low_camera();
        let screen = 160.0 * 128.0;
        let near = groups_ahead(&camera, 4, 6);
        let px = trees_px(&[camera], &near);
        // Their discs, each bounded by the screen, add up to many screens;
        // shared, they cover it once, in proportion.
        let discs: f64 = near.iter().map(|t| disc_px(&camera, t).min(screen)).sum();
        assert!(discs > 10.0 * screen, "{discs}");
        assert!((px.iter().sum::<f64>() / screen - 1.0).abs() < 1e-9, "{px:?}");
        let ratio = |k: usize| px[k] / disc_px(&camera, &near[k]).min(screen);
        assert!((0..near.len()).all(|k| (ratio(k) / ratio(0) - 1.0).abs() < 1e-9));
        // Groups whose discs leave room keep them; one out of view has none.
        let far: Vec<TreeItem> = near
            .iter()
            .map(|t| TreeItem { group: Item { radius_m: 5.0, ..t.group }, ..*t })
            .chain([TreeItem {
                group: Item { center_m: camera.position_ecef - camera.forward() * 300.0, ..near[0].group },
                ..near[0]
            }])
            .collect();
        let px = trees_px(&[camera], &far);
        assert!(px[..near.len()].iter().zip(&far).all(|(p, t)| *p == disc_px(&camera, t) && *p > 0.0), "{px:?}");
        assert_eq!(px[near.len()], 0.0);
    }

    #[test]
    fn tree_groups_around_a_low_camera_do_not_drop_the_terrain_to_its_coarsest_cut() {
        // Regression (demo_dive, 160 × 128, --budget-ms 100 on lavapipe):
        // as the first trees came into view, a dozen groups around the
        // camera each claimed the whole screen, the trees outweighed the
        // terrain several times over, and the cut fell from level 13 to
        // its roots (levels 5–8) for two frames.
        let camera = low_camera();
        let cameras = [camera];
        let steps = RaySteps::new(VIEW_STEPS);
        let range = |_| Some((1020.0, 1060.0));
        let scope = Scope { max_level: 14, limit: MAX_CANDIDATES, ..candidates::demo_scope(&cameras, &range, &steps) };
        let tiles = candidates::candidates(&scope).tiles;
        let roots = tiles.iter().filter(|c| c.parent.is_none()).count();
        let deepest = |cut: &Cut| cut.tiles.iter().map(|t| t.id.level).max().unwrap_or(0);
        // Tiles dear (0.5 ms each), splats 2 ms per thousand.
        let model = CostModel { constants_ms: [1.0, 0.5, 0.5, 0.5, 2.0, 0.01, 0.0, 0.0] };
        let trees = groups_ahead(&camera, 4, 6);
        let at = |ms: f64, trees: &[TreeItem]| {
            let budget = Budget { budget_ms: ms, max_tiles: 256, shadows: true, time_limit: None };
            cut_for(&cameras, &tiles, trees, (&model, &budget))
        };
        let (bare, with_trees) = (at(8.0, &[]), at(8.0, &trees));
        assert!(
            bare.tiles.len() > roots && deepest(&bare) >= 13,
            "{} tiles to level {}",
            bare.tiles.len(),
            deepest(&bare)
        );
        assert!(with_trees.predicted_ms <= 8.0 + 1e-9, "{}", with_trees.predicted_ms);
        assert!(
            with_trees.tiles.len() > roots && deepest(&with_trees) == deepest(&bare),
            "{} tiles to level {} ({roots} roots), {} splats",
            with_trees.tiles.len(),
            deepest(&with_trees),
            with_trees.features.splats_k * 1e3
        );
        // With room to spare, the trees get their splats on the same terrain.
        let (bare, rich) = (at(16.0, &[]), at(16.0, &trees));
        assert!(rich.features.splats_k > 1.0 && rich.tiles.len() == bare.tiles.len(), "{rich:?}");
    }
}
