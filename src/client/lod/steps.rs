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
//!
//! Under geomorphing a tile that refines the cut drawn is drawn as a morph
//! pair through its first interval: two surfaces read per height, bounds
//! enclosing both (in the demo's four-tile view 1.3 times the view and
//! twice the shadow fetches of the tile alone). Its measures are kept apart
//! from the tiles' own: the pairs' rays give the ratio of what they took
//! to what they were priced at alone (their ancestors' measures, for a
//! tile refined; a tile morphing down onto a coarser one, its own), over
//! the frames that drew pairs, the older weighing less
//! ([`PAIR_MEMORY`]), and a tile that will be drawn morphing is priced at
//! its own measure times that ratio ([`RaySteps::view`] with `morphs`).

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
    /// What the rays of tiles drawn as morph pairs took, and what they
    /// were priced at alone: view and shadow.
    pair: [Ratio; 2],
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
    /// The tiles drawn as morph pairs, apart from the tiles' own measures.
    pub pairs: Vec<Pair>,
}

/// The rays of a tile drawn as a morph pair in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pair {
    /// The tile.
    pub id: TileId,
    /// Its view-ray fetches, shadow-ray fetches and ray-cast pixels.
    pub sums: Sums,
    /// Its shadow steps.
    pub shadow_steps: u32,
}

/// Per tile: view fetches, shadow fetches, ray-cast pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sums {
    /// View-ray fetches.
    pub view: u64,
    /// Shadow-ray fetches.
    pub shadow: u64,
    /// Ray-cast pixels.
    pub pixels: u64,
}

impl FrameSteps {
    /// The rays of a frame whose pixels took `fetches` (view-ray fetches,
    /// 0 where no ray was cast; shadow-ray fetches) on the draw `draws`
    /// names (`k + 1` for draw `k` of `drawn`, 0 for none). The frame's
    /// mean leaves out the pixels of tiles drawn as morph pairs.
    pub fn measure(fetches: &[[u32; 2]], draws: &[u32], drawn: &[Choice]) -> FrameSteps {
        let mut sums = vec![Sums::default(); drawn.len()];
        let (mut total, mut pixels) = (0u64, 0u64);
        for (f, &d) in fetches.iter().zip(draws).filter(|(f, _)| f[0] > 0) {
            let k = (d as usize).checked_sub(1).filter(|&k| k < drawn.len());
            if k.is_none_or(|k| !drawn[k].morphs) {
                total += u64::from(f[0]);
                pixels += 1;
            }
            if let Some(s) = k.map(|k| &mut sums[k]) {
                (s.view, s.shadow, s.pixels) = (s.view + u64::from(f[0]), s.shadow + u64::from(f[1]), s.pixels + 1);
            }
        }
        let (pairs, own): (Vec<_>, Vec<_>) = drawn.iter().zip(sums).partition(|(c, _)| c.morphs);
        let view = own.iter().map(|(c, s)| (c.id, s.view, s.pixels)).collect();
        let shadow = own.iter().map(|(c, s)| (c.id, s.shadow, s.pixels * u64::from(c.shadow_steps))).collect();
        let (view, shadow) = (Means::of(view, Some((total, pixels))), Means::of(shadow, None));
        let pairs = pairs.into_iter().filter(|(_, s)| s.pixels > 0);
        let pairs = pairs.map(|(c, sums)| Pair { id: c.id, sums, shadow_steps: c.shadow_steps }).collect();
        FrameSteps { view, shadow, pairs }
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
        RaySteps {
            view: PerTile::new(view_prior),
            shadow: PerTile::new(SHADOW_FETCHES_PER_STEP),
            pair: [Ratio::default(); 2],
            frame: 0,
        }
    }

    /// View-ray steps per ray-cast pixel of the last frame that cast rays
    /// (or the prior).
    pub fn view_mean(&self) -> f64 {
        self.view.mean
    }

    /// View-ray steps per ray-cast pixel to price tile `id` with, drawn
    /// as a morph pair if it `morphs`.
    pub fn view(&self, id: TileId, morphs: bool) -> f64 {
        self.view.of(id, self.frame) * if morphs { self.pair[0].value() } else { 1.0 }
    }

    /// Shadow-ray fetches per ray-cast pixel and shadow step to price tile
    /// `id` with (at least [`SHADOW_FETCHES_FLOOR`]), times the pairs'
    /// ratio if it is drawn as a morph pair (`morphs`).
    pub fn shadow(&self, id: TileId, morphs: bool) -> f64 {
        let pair = if morphs { self.pair[1].value() } else { 1.0 };
        self.shadow.of(id, self.frame).max(SHADOW_FETCHES_FLOOR) * pair
    }

    /// Records a drawn frame; a frame without ray-cast pixels (or without
    /// shadow rays, or without morph pairs) leaves the mean (the pairs'
    /// ratio) as it was.
    pub fn record(&mut self, measured: &FrameSteps) {
        self.record_pairs(&measured.pairs);
        self.frame += 1;
        self.view.record(&measured.view, self.frame);
        self.shadow.record(&measured.shadow, self.frame);
    }

    /// Adds what the `pairs`' rays took and what they were priced at
    /// alone, before this frame's measures price them.
    fn record_pairs(&mut self, pairs: &[Pair]) {
        if pairs.is_empty() {
            return;
        }
        let (view, shadow, frame) = (&self.view, &self.shadow, self.frame);
        let took: f64 = pairs.iter().map(|p| p.sums.view as f64).sum();
        let priced: f64 = pairs.iter().map(|p| p.sums.pixels as f64 * view.of(p.id, frame)).sum();
        self.pair[0].add(took, priced);
        let shadowed = || pairs.iter().filter(|p| p.shadow_steps > 0);
        let took: f64 = shadowed().map(|p| p.sums.shadow as f64).sum();
        let steps = |p: &Pair| (p.sums.pixels * u64::from(p.shadow_steps)) as f64;
        let priced: f64 = shadowed().map(|p| steps(p) * shadow.of(p.id, frame).max(SHADOW_FETCHES_FLOOR)).sum();
        self.pair[1].add(took, priced);
    }
}

/// Weight of a frame's morph pairs against the next frame's that draws
/// some: a pair seen in a sliver of the screen moves the ratio by its
/// share of the pixels, and the pairs of the last few frames with pairs
/// make it.
pub const PAIR_MEMORY: f64 = 0.75;

/// What rays took over what they were priced at, summed over frames with
/// weights [`PAIR_MEMORY`]`^age`.
#[derive(Clone, Copy, Debug, Default)]
struct Ratio {
    took: f64,
    priced: f64,
}

impl Ratio {
    /// The ratio; 1 before anything was priced.
    fn value(&self) -> f64 {
        if self.priced > 0.0 { self.took / self.priced } else { 1.0 }
    }

    /// Adds a frame's, if it priced anything.
    fn add(&mut self, took: f64, priced: f64) {
        if priced > 0.0 && priced.is_finite() && took.is_finite() {
            self.took = PAIR_MEMORY * self.took + took;
            self.priced = PAIR_MEMORY * self.priced + priced;
        }
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

    #[test]
    fn a_frame_is_measured_per_tile_over_its_ray_cast_pixels() {
        let ids = [TileId::new(5, 1, 2), TileId::new(5, 1, 3), TileId::new(6, 0, 0)];
        let drawn = [(ids[0], 2), (ids[1], 0), (ids[2], 5)].map(|(id, shadow_steps)| Choice {
            id,
            shadow_steps,
            morphs: false,
        });
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
        assert_eq!(steps.shadow(ids[2], false), SHADOW_FETCHES_FLOOR);
    }

    #[test]
    fn a_tile_is_priced_by_itself_then_its_ancestors_then_the_mean() {
        let mut steps = RaySteps::new(20.0);
        let coarse = TileId::new(4, 3, 5);
        let near = TileId::new(6, 12, 20);
        assert_eq!((steps.view(near, false), steps.shadow(near, false)), (20.0, SHADOW_FETCHES_PER_STEP), "the priors");
        let shadow = Means { mean: Some(1.5), tiles: vec![(coarse, 1.8)] };
        steps.record(&FrameSteps { shadow, ..view_only(30.0, vec![(coarse, 40.0), (near, 8.0)]) });
        assert_eq!(steps.view(near, false), 8.0);
        assert_eq!(steps.view(coarse, false), 40.0);
        // A descendant of the coarse tile not drawn: its ancestor's steps;
        // through the near one, the near one's.
        assert_eq!(steps.view(TileId::new(7, 24, 40), false), 8.0);
        assert_eq!(steps.view(TileId::new(5, 6, 11), false), 40.0);
        // Elsewhere, and above both: the frame's mean.
        assert_eq!(steps.view(TileId::new(4, 0, 0), false), 30.0);
        assert_eq!(steps.view(TileId::new(3, 1, 2), false), 30.0);
        // Shadow rays likewise: the near tile, drawn without, its ancestor's.
        assert_eq!(
            (steps.shadow(near, false), steps.shadow(coarse, false), steps.shadow(TileId::new(4, 0, 0), false)),
            (1.8, 1.8, 1.5)
        );
    }

    #[test]
    fn morph_pairs_are_measured_apart_and_price_the_tiles_that_will_morph() {
        let (coarse, fine) = (TileId::new(5, 1, 2), TileId::new(6, 2, 4));
        let mut steps = RaySteps::new(20.0);
        let shadow = Means { mean: Some(1.0), tiles: vec![(coarse, 1.0)] };
        steps.record(&FrameSteps { shadow, ..view_only(12.0, vec![(coarse, 10.0)]) });
        assert_eq!((steps.view(fine, true), steps.shadow(fine, true)), (10.0, 1.0), "no pair measured yet");
        // The fine tile drawn as a pair refining the coarse one: two pixels
        // of 15 view fetches and 2 shadow steps of 2 fetches each.
        let drawn = [Choice { id: fine, shadow_steps: 2, morphs: true }];
        let m = FrameSteps::measure(&[[15, 4], [15, 4], [0, 0]], &[1, 1, 0], &drawn);
        let sums = Sums { view: 30, shadow: 8, pixels: 2 };
        assert_eq!(m.pairs, vec![Pair { id: fine, sums, shadow_steps: 2 }]);
        assert_eq!((m.view.mean, m.view.tiles.len(), m.shadow.tiles.len()), (None, 0, 0), "not the tile's own");
        steps.record(&m);
        // Priced alone as before (its ancestor's, the frame's mean kept);
        // as a pair, 1.5 times the view and twice the shadow fetches.
        assert_eq!((steps.view(fine, false), steps.view_mean(), steps.shadow(fine, false)), (10.0, 12.0, 1.0));
        assert_eq!((steps.view(fine, true), steps.shadow(fine, true)), (15.0, 2.0));
        assert_eq!(steps.view(TileId::new(4, 9, 9), true), 18.0, "elsewhere, the mean as a pair");
        // A frame without pairs keeps the ratios.
        steps.record(&view_only(12.0, vec![(coarse, 10.0)]));
        assert_eq!((steps.view(fine, true), steps.shadow(fine, true)), (15.0, 2.0));
        // Later pairs weigh in by their pixels, the earlier at PAIR_MEMORY:
        // one pixel at 40 fetches (4 times its price), without shadow rays.
        let drawn = [Choice { shadow_steps: 0, ..drawn[0] }];
        steps.record(&FrameSteps::measure(&[[40, 0]], &[1], &drawn));
        let view = (PAIR_MEMORY * 30.0 + 40.0) / (PAIR_MEMORY * 20.0 + 10.0);
        assert!((steps.view(fine, true) - 10.0 * view).abs() < 1e-12, "{}", steps.view(fine, true));
        assert_eq!(steps.shadow(fine, true), 2.0, "no shadow rays: that ratio kept");
    }

    #[test]
    fn a_pairs_shadow_ratio_is_taken_against_the_floored_price() {
        // Review: shadow rays that all but stopped at once on the coarse
        // tile (0.01 fetches a step, priced at the floor 0.1) and took 0.5
        // on its refinement drawn as a pair made a ratio of 50, which
        // priced every other tile's morph at 50 times its own.
        let (coarse, fine, other) = (TileId::new(5, 1, 2), TileId::new(6, 2, 4), TileId::new(5, 9, 9));
        let mut steps = RaySteps::new(20.0);
        let shadow = Means { mean: Some(1.0), tiles: vec![(coarse, 0.01), (other, 1.0)] };
        steps.record(&FrameSteps { shadow, ..view_only(12.0, vec![(coarse, 10.0), (other, 10.0)]) });
        let drawn = [Choice { id: fine, shadow_steps: 2, morphs: true }];
        steps.record(&FrameSteps::measure(&[[10, 1], [10, 1]], &[1, 1], &drawn));
        assert_eq!((steps.shadow(fine, true), steps.shadow(other, true)), (0.5, 5.0));
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
            (steps.view(tile, false), steps.shadow(tile, false)),
            (40.0, 0.7),
            "drawn within the last {MAX_AGE_FRAMES} frames"
        );
        steps.record(&FrameSteps::default());
        assert_eq!(
            (steps.view(tile, false), steps.view_mean(), steps.shadow(tile, false)),
            (30.0, 30.0, 0.8),
            "aged out; the means stay"
        );
        assert!(steps.view.tiles.is_empty() && steps.shadow.tiles.is_empty(), "and forgotten");
        steps.record(&view_only(12.0, vec![(tile, 11.0)]));
        assert_eq!(steps.view(tile, false), 11.0);
    }
}
