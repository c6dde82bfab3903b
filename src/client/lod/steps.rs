//! Ray work per ray cast, tile by tile, as the renderer counted it
//! ([`crate::client::render::DrawWork`]: every ray, the hidden ones too):
//! what a tile's rays cost depends on how they meet it. Grazing a
//! coarse tile toward the horizon a view ray walks many cells near the
//! surface; plunging into a near fine one it descends the mipmap and stops
//! (one rmnp frame holds tiles at 8 and at 40 steps a pixel). A shadow ray
//! stops once it climbs above the tile's highest sample, and under a fading
//! canopy each of its steps reads the ground too (over the demo valley one
//! tile's shadow rays fetch 0.8 times their steps, its neighbour's 1.6 or
//! 2). Priced at one flight-wide figure, a cut that trades far coarse tiles
//! for near fine ones looks as dear as it was, and the frame comes in under
//! (or over) the budget. The leaf cells a view ray reads are counted apart
//! from its fetches: a leaf's corners and patch test cost several steps
//! over the maximum mipmap, and grazing rays walk many leaves (over the demo
//! valley a frame's leaves were 23–67 % of its fetches, and frames of the
//! same fetches took up to twice as long with more of them).
//!
//! A tile is priced with what its rays took when it was last drawn (its
//! shadow rays: per shadow step, when it was last drawn with some); a tile
//! not drawn within [`MAX_AGE_FRAMES`], with its nearest ancestor's that
//! was (refining keeps the view's geometry); else with the mean of the last
//! frame that cast such rays.

use super::budget::Choice;
use crate::client::render::DrawWork;
use crate::grid::TileId;
use std::collections::HashMap;

/// View-ray steps per ray cast before any is measured (the exact
/// traversal's mean on the demo and rmnp paths is 10–30 fetches).
pub const VIEW_STEPS: f64 = 20.0;

/// Leaf cells a view ray reads before any is measured (over the demo valley
/// 3–9 a ray).
pub const LEAF_CELLS: f64 = 5.0;

/// Shadow-ray fetches per shadow step before any is measured: one height
/// a step, every step taken.
pub const SHADOW_FETCHES_PER_STEP: f64 = 1.0;

/// Least shadow-ray fetches per step a tile is priced at: rays that all
/// stopped at once cost their set-up, and given more steps they may not
/// stop at once (a tile priced at nothing would take the most steps).
pub const SHADOW_FETCHES_FLOOR: f64 = 0.1;

/// Frames after which a tile's measurements no longer price it: the
/// camera has moved on (a second at 30 frames/s).
pub const MAX_AGE_FRAMES: u64 = 32;

/// The rays' work the renderer measured lately, per tile.
#[derive(Clone, Debug)]
pub struct RaySteps {
    /// View-ray fetches per ray cast.
    view: PerTile,
    /// Leaf cells read per ray cast.
    leaf: PerTile,
    /// Shadow-ray fetches per ray cast and shadow step.
    shadow: PerTile,
    /// Frames recorded.
    frame: u64,
}

/// One measure of the frames recorded: the last frame's mean, and per tile.
#[derive(Clone, Debug)]
struct PerTile {
    mean: f64,
    tiles: HashMap<TileId, Measured>,
}

#[derive(Clone, Copy, Debug)]
struct Measured {
    value: f64,
    frame: u64,
}

/// One frame's means of one measure: over the frame, and per tile.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Means {
    /// Over the frame (none if nothing was measured).
    pub mean: Option<f64>,
    /// Over each tile measured.
    pub tiles: Vec<(TileId, f64)>,
}

/// One frame's rays: view-ray fetches and leaf cells per ray cast, and
/// shadow-ray fetches per ray cast and shadow step (of the tiles drawn with
/// shadow steps).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameSteps {
    /// View rays' fetches.
    pub view: Means,
    /// View rays' leaf cells.
    pub leaf: Means,
    /// Shadow rays.
    pub shadow: Means,
}

impl FrameSteps {
    /// The rays of a frame whose draws did `work` (draw `k` is tile `k` of
    /// `drawn`).
    pub fn measure(work: &[DrawWork], drawn: &[Choice]) -> FrameSteps {
        let tiles = || drawn.iter().zip(work);
        let per_ray = |count: fn(&DrawWork) -> u64| Means::of(tiles().map(|(c, w)| (c.id, count(w), w.rays)).collect());
        let shadow = tiles().map(|(c, w)| (c.id, w.shadow_fetches, w.rays * u64::from(c.shadow_steps))).collect();
        FrameSteps { view: per_ray(|w| w.view_fetches), leaf: per_ray(|w| w.leaf_cells), shadow: Means::of(shadow) }
    }
}

impl Means {
    /// Each tile's sum over its count (those counted), and the mean: the
    /// tiles' sums over their counts.
    fn of(tiles: Vec<(TileId, u64, u64)>) -> Means {
        let (n, d) = tiles.iter().fold((0, 0), |(n, d), t| (n + t.1, d + t.2));
        let counted = tiles.iter().filter(|t| t.2 > 0).map(|&(id, n, d)| (id, n as f64 / d as f64));
        Means { mean: (d > 0).then(|| n as f64 / d as f64), tiles: counted.collect() }
    }
}

impl RaySteps {
    /// Nothing measured yet: every tile's view rays at `view_prior` steps
    /// and [`LEAF_CELLS`] leaves, its shadow rays at
    /// [`SHADOW_FETCHES_PER_STEP`].
    pub fn new(view_prior: f64) -> RaySteps {
        RaySteps {
            view: PerTile::new(view_prior),
            leaf: PerTile::new(LEAF_CELLS),
            shadow: PerTile::new(SHADOW_FETCHES_PER_STEP),
            frame: 0,
        }
    }

    /// View-ray steps per ray cast of the last frame that cast rays (or the
    /// prior).
    pub fn view_mean(&self) -> f64 {
        self.view.mean
    }

    /// View-ray steps per ray cast to price tile `id` with.
    pub fn view(&self, id: TileId) -> f64 {
        self.view.of(id, self.frame)
    }

    /// Leaf cells per view ray to price tile `id` with.
    pub fn leaf(&self, id: TileId) -> f64 {
        self.leaf.of(id, self.frame)
    }

    /// Shadow-ray fetches per ray cast and shadow step to price tile `id`
    /// with (at least [`SHADOW_FETCHES_FLOOR`]).
    pub fn shadow(&self, id: TileId) -> f64 {
        self.shadow.of(id, self.frame).max(SHADOW_FETCHES_FLOOR)
    }

    /// Records a drawn frame; a frame without ray-cast pixels (or without
    /// shadow rays) leaves the mean as it was.
    pub fn record(&mut self, measured: &FrameSteps) {
        self.frame += 1;
        self.view.record(&measured.view, self.frame);
        self.leaf.record(&measured.leaf, self.frame);
        self.shadow.record(&measured.shadow, self.frame);
    }
}

impl PerTile {
    fn new(prior: f64) -> PerTile {
        PerTile { mean: prior, tiles: HashMap::new() }
    }

    /// The value of `id`, else of its nearest ancestor, measured within
    /// [`MAX_AGE_FRAMES`] of `frame`; else the mean.
    fn of(&self, id: TileId, frame: u64) -> f64 {
        std::iter::successors(Some(id), TileId::parent)
            .find_map(|t| self.tiles.get(&t).filter(|m| frame - m.frame < MAX_AGE_FRAMES))
            .map_or(self.mean, |m| m.value)
    }

    fn record(&mut self, measured: &Means, frame: u64) {
        if let Some(mean) = measured.mean.filter(|m| m.is_finite() && *m >= 0.0) {
            self.mean = mean;
        }
        for &(id, value) in measured.tiles.iter().filter(|(_, v)| v.is_finite() && *v >= 0.0) {
            self.tiles.insert(id, Measured { value, frame });
        }
        self.tiles.retain(|_, m| frame - m.frame < MAX_AGE_FRAMES);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame of view rays only, `mean` steps over the frame.
    fn view_only(mean: f64, tiles: Vec<(TileId, f64)>) -> FrameSteps {
        FrameSteps { view: Means { mean: Some(mean), tiles }, ..FrameSteps::default() }
    }

    /// `rays` rays that took `view` fetches and `leaf` leaves, and `shadow`
    /// shadow fetches.
    fn work(rays: u64, view: u64, leaf: u64, shadow: u64) -> DrawWork {
        DrawWork { rays, view_fetches: view, leaf_cells: leaf, shadow_fetches: shadow }
    }

    #[test]
    fn a_frame_is_measured_per_tile_over_its_rays() {
        let ids = [TileId::new(5, 1, 2), TileId::new(5, 1, 3), TileId::new(6, 0, 0)];
        let drawn = [(ids[0], 2), (ids[1], 0), (ids[2], 5)].map(|(id, shadow_steps)| Choice { id, shadow_steps });
        // Two rays on the first tile, one on the second (drawn without
        // shadow steps); the third tile casts none.
        let m = FrameSteps::measure(&[work(2, 30, 6, 12), work(1, 40, 9, 0), work(0, 0, 0, 0)], &drawn);
        assert_eq!(m.view, Means { mean: Some(70.0 / 3.0), tiles: vec![(ids[0], 15.0), (ids[1], 40.0)] });
        assert_eq!(m.leaf, Means { mean: Some(5.0), tiles: vec![(ids[0], 3.0), (ids[1], 9.0)] });
        // 12 shadow fetches over 2 rays of 2 steps.
        assert_eq!(m.shadow, Means { mean: Some(3.0), tiles: vec![(ids[0], 3.0)] });
        assert_eq!(FrameSteps::measure(&[DrawWork::default(); 3], &drawn), FrameSteps::default());
        // Shadow rays that all stop at once: measured, at nothing.
        let m = FrameSteps::measure(&[DrawWork::default(), DrawWork::default(), work(1, 10, 2, 0)], &drawn);
        assert_eq!(m.shadow, Means { mean: Some(0.0), tiles: vec![(ids[2], 0.0)] });
        // ... and priced at the floor: given more steps they may not stop.
        let mut steps = RaySteps::new(20.0);
        steps.record(&m);
        assert_eq!(steps.shadow(ids[2]), SHADOW_FETCHES_FLOOR);
        assert_eq!((steps.view(ids[2]), steps.leaf(ids[2]), steps.leaf(ids[0])), (10.0, 2.0, 2.0), "the frame's mean");
    }

    #[test]
    fn a_tile_is_priced_by_itself_then_its_ancestors_then_the_mean() {
        let mut steps = RaySteps::new(20.0);
        let coarse = TileId::new(4, 3, 5);
        let near = TileId::new(6, 12, 20);
        assert_eq!((steps.view(near), steps.shadow(near)), (20.0, SHADOW_FETCHES_PER_STEP), "the priors");
        let shadow = Means { mean: Some(1.5), tiles: vec![(coarse, 1.8)] };
        steps.record(&FrameSteps { shadow, ..view_only(30.0, vec![(coarse, 40.0), (near, 8.0)]) });
        assert_eq!(steps.view(near), 8.0);
        assert_eq!(steps.view(coarse), 40.0);
        // A descendant of the coarse tile not drawn: its ancestor's steps;
        // through the near one, the near one's.
        assert_eq!(steps.view(TileId::new(7, 24, 40)), 8.0);
        assert_eq!(steps.view(TileId::new(5, 6, 11)), 40.0);
        // Elsewhere, and above both: the frame's mean.
        assert_eq!(steps.view(TileId::new(4, 0, 0)), 30.0);
        assert_eq!(steps.view(TileId::new(3, 1, 2)), 30.0);
        // Shadow rays likewise: the near tile, drawn without, its ancestor's.
        assert_eq!((steps.shadow(near), steps.shadow(coarse), steps.shadow(TileId::new(4, 0, 0))), (1.8, 1.8, 1.5));
    }

    #[test]
    fn measurements_age_out_and_frames_without_rays_keep_the_mean() {
        let mut steps = RaySteps::new(20.0);
        let tile = TileId::new(4, 3, 5);
        let shadow = Means { mean: Some(0.8), tiles: vec![(tile, 0.7)] };
        steps.record(&FrameSteps { shadow, ..view_only(30.0, vec![(tile, 40.0)]) });
        for _ in 1..MAX_AGE_FRAMES {
            steps.record(&FrameSteps::default());
        }
        assert_eq!(
            (steps.view(tile), steps.shadow(tile)),
            (40.0, 0.7),
            "drawn within the last {MAX_AGE_FRAMES} frames"
        );
        steps.record(&FrameSteps::default());
        assert_eq!(
            (steps.view(tile), steps.view_mean(), steps.shadow(tile)),
            (30.0, 30.0, 0.8),
            "aged out; the means stay"
        );
        assert!(steps.view.tiles.is_empty() && steps.shadow.tiles.is_empty(), "and forgotten");
        steps.record(&view_only(12.0, vec![(tile, 11.0)]));
        assert_eq!(steps.view(tile), 11.0);
    }
}
