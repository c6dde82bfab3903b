//! Ray fetches per ray-cast pixel, tile by tile, as the renderer measured
//! them: what a tile's rays cost depends on how they meet it. Grazing a
//! coarse tile toward the horizon a view ray walks many cells near the
//! surface; plunging into a near fine one it descends the mipmap and stops
//! (one rmnp frame holds tiles at 8 and at 40 steps a pixel). A shadow ray
//! stops once it climbs above the tile's highest sample, and under a fading
//! canopy each of its steps reads the ground too (over the demo valley one
//! tile's shadow rays fetch 0.8 times their steps, its neighbour's 1.6 or
//! 2). Priced at one flight-wide figure, a cut that trades far coarse tiles
//! for near fine ones looks as dear as it was, and the frame comes in under
//! (or over) the budget.
//!
//! A tile is priced with what its rays took when it was last drawn (its
//! shadow rays: per shadow step, when it was last drawn with some); a tile
//! not drawn within [`MAX_AGE_FRAMES`], with its nearest ancestor's that
//! was (refining keeps the view's geometry); else with the mean of the last
//! frame that cast such rays.

use super::budget::Choice;
use crate::grid::TileId;
use std::collections::HashMap;

/// View-ray steps per ray-cast pixel before any is measured (the exact
/// traversal's mean on the demo and rmnp paths is 10–30 fetches).
pub const VIEW_STEPS: f64 = 20.0;

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

/// The rays' fetches the renderer measured lately, per tile.
#[derive(Clone, Debug)]
pub struct RaySteps {
    /// View-ray fetches per ray-cast pixel.
    view: PerTile,
    /// Shadow-ray fetches per ray-cast pixel and shadow step.
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

/// One frame's rays: view-ray fetches per ray-cast pixel, and shadow-ray
/// fetches per ray-cast pixel and shadow step (of the tiles drawn with
/// shadow steps).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameSteps {
    /// View rays.
    pub view: Means,
    /// Shadow rays.
    pub shadow: Means,
}

/// Per tile: view fetches, shadow fetches, ray-cast pixels.
#[derive(Clone, Copy, Default)]
struct Sums {
    view: u64,
    shadow: u64,
    pixels: u64,
}

impl FrameSteps {
    /// The rays of a frame whose pixels took `fetches` (view-ray fetches,
    /// 0 where no ray was cast; shadow-ray fetches) on the draw `draws`
    /// names (`k + 1` for draw `k` of `drawn`, 0 for none).
    pub fn measure(fetches: &[[u32; 2]], draws: &[u32], drawn: &[Choice]) -> FrameSteps {
        let mut sums = vec![Sums::default(); drawn.len()];
        let (mut total, mut pixels) = (0u64, 0u64);
        for (f, &d) in fetches.iter().zip(draws).filter(|(f, _)| f[0] > 0) {
            total += u64::from(f[0]);
            pixels += 1;
            if let Some(s) = (d as usize).checked_sub(1).and_then(|k| sums.get_mut(k)) {
                (s.view, s.shadow, s.pixels) = (s.view + u64::from(f[0]), s.shadow + u64::from(f[1]), s.pixels + 1);
            }
        }
        let tiles = || drawn.iter().zip(&sums);
        let view = tiles().map(|(c, s)| (c.id, s.view, s.pixels)).collect();
        let shadow = tiles().map(|(c, s)| (c.id, s.shadow, s.pixels * u64::from(c.shadow_steps))).collect();
        let (view, shadow) = (Means::of(view, Some((total, pixels))), Means::of(shadow, None));
        FrameSteps { view, shadow }
    }
}

impl Means {
    /// Each tile's sum over its count (those counted), and the mean:
    /// `total` over its count, or the tiles' sums over their counts.
    fn of(tiles: Vec<(TileId, u64, u64)>, total: Option<(u64, u64)>) -> Means {
        let summed = || tiles.iter().fold((0, 0), |(n, d), t| (n + t.1, d + t.2));
        let (n, d) = total.unwrap_or_else(summed);
        let counted = tiles.iter().filter(|t| t.2 > 0).map(|&(id, n, d)| (id, n as f64 / d as f64));
        Means { mean: (d > 0).then(|| n as f64 / d as f64), tiles: counted.collect() }
    }
}

impl RaySteps {
    /// Nothing measured yet: every tile's view rays at `view_prior` steps,
    /// its shadow rays at [`SHADOW_FETCHES_PER_STEP`].
    pub fn new(view_prior: f64) -> RaySteps {
        RaySteps { view: PerTile::new(view_prior), shadow: PerTile::new(SHADOW_FETCHES_PER_STEP), frame: 0 }
    }

    /// View-ray steps per ray-cast pixel of the last frame that cast rays
    /// (or the prior).
    pub fn view_mean(&self) -> f64 {
        self.view.mean
    }

    /// View-ray steps per ray-cast pixel to price tile `id` with.
    pub fn view(&self, id: TileId) -> f64 {
        self.view.of(id, self.frame)
    }

    /// Shadow-ray fetches per ray-cast pixel and shadow step to price tile
    /// `id` with (at least [`SHADOW_FETCHES_FLOOR`]).
    pub fn shadow(&self, id: TileId) -> f64 {
        self.shadow.of(id, self.frame).max(SHADOW_FETCHES_FLOOR)
    }

    /// Records a drawn frame; a frame without ray-cast pixels (or without
    /// shadow rays) leaves the mean as it was.
    pub fn record(&mut self, measured: &FrameSteps) {
        self.frame += 1;
        self.view.record(&measured.view, self.frame);
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
        FrameSteps { view: Means { mean: Some(mean), tiles }, shadow: Means::default() }
    }

    #[test]
    fn a_frame_is_measured_per_tile_over_its_ray_cast_pixels() {
        let ids = [TileId::new(5, 1, 2), TileId::new(5, 1, 3), TileId::new(6, 0, 0)];
        let drawn = [(ids[0], 2), (ids[1], 0), (ids[2], 5)].map(|(id, shadow_steps)| Choice { id, shadow_steps });
        // Pixels: two on the first tile, one on the second (drawn without
        // shadow steps), one plain pixel (no fetches) and one sky pixel; the
        // third tile casts no rays.
        let fetches = [[10, 4], [20, 8], [40, 0], [0, 0], [0, 0]];
        let draws = [1, 1, 2, 3, 0];
        let m = FrameSteps::measure(&fetches, &draws, &drawn);
        assert_eq!(m.view, Means { mean: Some(70.0 / 3.0), tiles: vec![(ids[0], 15.0), (ids[1], 40.0)] });
        // 12 shadow fetches over 2 pixels of 2 steps.
        assert_eq!(m.shadow, Means { mean: Some(3.0), tiles: vec![(ids[0], 3.0)] });
        assert_eq!(FrameSteps::measure(&[[0, 0], [0, 0]], &[0, 1], &drawn), FrameSteps::default());
        // Shadow rays that all stop at once: measured, at nothing.
        let m = FrameSteps::measure(&[[10, 0]], &[3], &drawn);
        assert_eq!(m.shadow, Means { mean: Some(0.0), tiles: vec![(ids[2], 0.0)] });
        // ... and priced at the floor: given more steps they may not stop.
        let mut steps = RaySteps::new(20.0);
        steps.record(&m);
        assert_eq!(steps.shadow(ids[2]), SHADOW_FETCHES_FLOOR);
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
