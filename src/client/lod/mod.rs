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
use candidates::Scope;
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
        let seen: Vec<(TreeItem, f64)> = trees.iter().map(|t| (*t, tree_px(cameras, t))).collect();
        let cut = budget::choose(&found.tiles, &seen, model, budget);
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

/// Pixels a tree group covers from the best placed of `cameras`: its
/// bounding sphere's projected disc, at most the screen, none outside the
/// view.
fn tree_px(cameras: &[Camera], t: &TreeItem) -> f64 {
    cameras
        .iter()
        .filter(|c| c.side_planes().iter().all(|n| n.dot(t.group.center_m - c.position_ecef) >= -t.group.radius_m))
        .map(|c| {
            let d = (t.group.center_m.distance(c.position_ecef) - t.group.radius_m).max(1.0);
            let r_px = t.group.radius_m * c.focal_px() / d;
            (std::f64::consts::PI * r_px * r_px).min(f64::from(c.width_px) * f64::from(c.height_px))
        })
        .fold(0.0, f64::max)
}
