//! The screen-space error selection of a flight (`sylva fly --lod sse`),
//! kept from frame to frame so that its work follows the camera's motion,
//! not the number of tiles (004 §V).
//!
//! The rule, in the sphere form the deferral table needs: a tile is refined
//! while the eye is within `r + ξ μ` of its bounding sphere's centre — its
//! error `ξ` (sample spacing plus flat-frame error, [`super::tiletree`])
//! projects to more than `max_error_px` pixels at the nearest point of its
//! sphere, `μ = focal / max_error_px`. The sphere holds the tile's culling
//! box, so this refines wherever the box rule of [`super::quadtree::select`]
//! does, and a little further (never a coarser image); its bounds are static
//! (heights known before the flight), so the rule has bounded variation.
//!
//! [`SseSelector::deferred`] keeps the refined set with a
//! [`ThresholdRefiner`]: a frame re-tests only the tiles whose buckets the
//! eye's travel has passed. [`SseSelector::full`] re-tests every tile from
//! the roots each frame (the reference: both refine exactly alike, tested
//! along the recorded flyovers). Culling follows refinement ([`super::cull`]).
//! A new threshold (the flight raises it when the GPU cache is too small)
//! starts the table again.

use super::camera::Camera;
use super::cull;
use super::envelope::HeightEnvelope;
use super::quadtree::{LodRule, Selection};
use super::source::{FetchError, TileSource};
use super::tiletree::TileTree;
use crate::grid::{BBox, TileGrid};
use crate::lod::deferral::{Hierarchy, ThresholdRefiner, full_refinement};

/// Buckets of each deferral table: a bucket is ~1.2 m of travel, about a
/// frame's at 60 frames/s for a slow flight. The head passes at least one
/// bucket a frame, so coarser buckets re-test slow flights' tiles early
/// (1024 buckets: 2–3× the tests at 60 frames/s, `sylva bench sse`).
const BUCKETS: usize = 8192;
/// Travel the tables span, metres: about the reach `r + ξ μ` of a level-8
/// tile (36° / 513-sample grid, μ ≈ 200), beyond which slacks are rounded
/// down.
const TABLE_RANGE_M: f64 = 10_000.0;

/// How the refined set is kept.
#[derive(Clone, Debug)]
enum Refinement {
    /// By the deferral table, with the `μ` it was started for.
    Deferred(Option<(f64, ThresholdRefiner)>),
    /// Tested in full every frame (flags per node).
    Full(Vec<bool>),
}

/// A flight's screen-space error selection.
#[derive(Clone, Debug)]
pub struct SseSelector {
    tree: TileTree,
    refinement: Refinement,
}

impl SseSelector {
    /// Deferred re-evaluation over `tree`.
    pub fn deferred(tree: TileTree) -> SseSelector {
        SseSelector { tree, refinement: Refinement::Deferred(None) }
    }

    /// Full re-evaluation over `tree` every frame.
    pub fn full(tree: TileTree) -> SseSelector {
        let flags = vec![false; tree.len()];
        SseSelector { tree, refinement: Refinement::Full(flags) }
    }

    /// [`Self::over`] `source`'s region, its coarse tiles fetched.
    pub fn for_source(source: &dyn TileSource, max_level: u32) -> Result<Option<SseSelector>, FetchError> {
        let envelope = HeightEnvelope::fetch(source)?;
        Ok(SseSelector::over(&source.grid(), &source.bounds(), &envelope, max_level))
    }

    /// The deferred selector over the region `bounds` on `grid` down to
    /// `max_level`, bounds from its coarse tiles' `envelope`; `None` if the
    /// region's tree is too large to hold ([`super::tiletree::MAX_NODES`]).
    pub fn over(grid: &TileGrid, bounds: &BBox, envelope: &HeightEnvelope, max_level: u32) -> Option<SseSelector> {
        let tree = TileTree::build(grid, bounds, max_level, &|s| envelope.range(s));
        tree.ok().map(SseSelector::deferred)
    }

    /// The tree selected from.
    pub fn tree(&self) -> &TileTree {
        &self.tree
    }

    /// The tiles for `camera` by `rule` (its error, and no level deeper
    /// than its own or the tree's); `visited` counts the refinement and
    /// visibility tests.
    pub fn select(&mut self, camera: &Camera, rule: &LodRule) -> Selection {
        let mu = camera.focal_px() / rule.max_error_px;
        let eye = camera.position_ecef;
        let tree = &self.tree;
        let (evaluated, refined): (usize, &[bool]) = match &mut self.refinement {
            Refinement::Full(flags) => (full_refinement(tree, mu, eye, flags), flags),
            Refinement::Deferred(state) => {
                if state.as_ref().is_some_and(|(m, _)| *m != mu) {
                    *state = None;
                }
                let (_, refiner) =
                    state.get_or_insert_with(|| (mu, ThresholdRefiner::new(tree.len(), mu, BUCKETS, TABLE_RANGE_M)));
                (refiner.update(tree, eye), refiner.refined())
            }
        };
        let (tiles, tests) = cull::drawn(tree, refined, camera, rule.max_level);
        Selection { tiles, visited: evaluated + tests, evaluated }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::globe::Geodetic;

    fn tree() -> TileTree {
        let grid = TileGrid::new(36.0, 513).unwrap();
        let bounds = BBox { west: 10.0, south: 46.3, east: 10.25, north: 46.45 };
        TileTree::build(&grid, &bounds, 13, &|_| Some((800.0, 3300.0))).unwrap()
    }

    #[test]
    fn a_changed_threshold_restarts_the_table_and_stays_exact() {
        let (mut deferred, mut full) = (SseSelector::deferred(tree()), SseSelector::full(tree()));
        for (k, px) in [2.0, 2.0, 2.5, 2.5, 2.0, 8.0].into_iter().enumerate() {
            let eye = Geodetic::new(10.1 + 0.002 * k as f64, 46.35, 2500.0 - 100.0 * k as f64);
            let camera = Camera::looking(eye, 30.0 * k as f64, -20.0, 60.0, (640, 480));
            let rule = LodRule { max_error_px: px, max_level: 13 };
            let (d, f) = (deferred.select(&camera, &rule), full.select(&camera, &rule));
            assert_eq!(d.tiles, f.tiles, "frame {k}");
            assert!(!d.tiles.is_empty());
            assert!(d.tiles.iter().all(|t| t.error_px <= px || t.id.level == 13), "frame {k}");
        }
    }
}
