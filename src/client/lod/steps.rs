//! View-ray steps per ray-cast pixel, tile by tile, as the renderer
//! measured them: what a tile's view rays cost depends on how they meet
//! it. Grazing a coarse tile toward the horizon a ray walks many cells
//! near the surface; plunging into a near fine one it descends the mipmap
//! and stops (one rmnp frame holds tiles at 8 and at 40 steps a pixel).
//! Priced at one flight-wide mean, a cut that trades far coarse tiles for
//! near fine ones looks as dear as it was, and the frame comes in under
//! (or over) the budget.
//!
//! A tile is priced with the steps its rays took when it was last drawn;
//! a tile not drawn within [`MAX_AGE_FRAMES`], with its nearest ancestor's
//! that was (refining keeps the view's geometry); else with the mean of the
//! last frame that cast rays.

use crate::grid::TileId;
use std::collections::HashMap;

/// View-ray steps per ray-cast pixel before any is measured (the exact
/// traversal's mean on the demo and rmnp paths is 10–30 fetches).
pub const VIEW_STEPS: f64 = 20.0;

/// Frames after which a tile's measured steps no longer price it: the
/// camera has moved on (a second at 30 frames/s).
pub const MAX_AGE_FRAMES: u64 = 32;

/// The view-ray steps the renderer measured lately, per tile.
#[derive(Clone, Debug)]
pub struct ViewSteps {
    /// Mean over the last frame's ray-cast pixels (or the prior).
    mean: f64,
    tiles: HashMap<TileId, Measured>,
    /// Frames recorded.
    frame: u64,
}

#[derive(Clone, Copy, Debug)]
struct Measured {
    steps: f64,
    frame: u64,
}

/// One frame's view-ray steps per ray-cast pixel: the mean, and per tile
/// that cast rays.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameSteps {
    /// Mean over the frame's ray-cast pixels (0 if none).
    pub mean: f64,
    /// Mean over each tile's ray-cast pixels.
    pub tiles: Vec<(TileId, f64)>,
}

impl FrameSteps {
    /// The steps of a frame whose pixels took `fetches` view-ray fetches
    /// (0 where no ray was cast) on the draw `draws` names (`k + 1` for
    /// draw `k` of `ids`, 0 for none).
    pub fn measure(fetches: &[u32], draws: &[u32], ids: &[TileId]) -> FrameSteps {
        let mut sums = vec![(0u64, 0u64); ids.len()];
        let (mut total, mut pixels) = (0u64, 0u64);
        for (&f, &d) in fetches.iter().zip(draws).filter(|(f, _)| **f > 0) {
            total += u64::from(f);
            pixels += 1;
            if let Some(s) = (d as usize).checked_sub(1).and_then(|k| sums.get_mut(k)) {
                *s = (s.0 + u64::from(f), s.1 + 1);
            }
        }
        let tiles = ids.iter().zip(&sums).filter(|(_, s)| s.1 > 0).map(|(&id, s)| (id, s.0 as f64 / s.1 as f64));
        FrameSteps { mean: total as f64 / pixels.max(1) as f64, tiles: tiles.collect() }
    }
}

impl ViewSteps {
    /// Nothing measured yet: every tile at `prior` steps.
    pub fn new(prior: f64) -> ViewSteps {
        ViewSteps { mean: prior, tiles: HashMap::new(), frame: 0 }
    }

    /// The mean of the last frame that cast rays (or the prior).
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Steps per ray-cast pixel to price tile `id` with.
    pub fn of(&self, id: TileId) -> f64 {
        std::iter::successors(Some(id), TileId::parent)
            .find_map(|t| self.tiles.get(&t).filter(|m| self.frame - m.frame < MAX_AGE_FRAMES))
            .map_or(self.mean, |m| m.steps)
    }

    /// Records a drawn frame's steps; a frame without ray-cast pixels
    /// leaves the mean as it was.
    pub fn record(&mut self, measured: &FrameSteps) {
        self.frame += 1;
        if measured.mean.is_finite() && measured.mean > 0.0 {
            self.mean = measured.mean;
        }
        let frame = self.frame;
        for &(id, steps) in measured.tiles.iter().filter(|(_, s)| s.is_finite() && *s > 0.0) {
            self.tiles.insert(id, Measured { steps, frame });
        }
        self.tiles.retain(|_, m| frame - m.frame < MAX_AGE_FRAMES);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_is_measured_per_tile_over_its_ray_cast_pixels() {
        let ids = [TileId::new(5, 1, 2), TileId::new(5, 1, 3), TileId::new(6, 0, 0)];
        // Pixels: two on the first tile, one on the second, one plain pixel
        // (no fetches) and one sky pixel; the third tile casts no rays.
        let fetches = [10, 20, 40, 0, 0];
        let draws = [1, 1, 2, 3, 0];
        let m = FrameSteps::measure(&fetches, &draws, &ids);
        assert_eq!(m.tiles, [(ids[0], 15.0), (ids[1], 40.0)]);
        assert!((m.mean - 70.0 / 3.0).abs() < 1e-12);
        assert_eq!(FrameSteps::measure(&[0, 0], &[0, 1], &ids), FrameSteps::default());
    }

    #[test]
    fn a_tile_is_priced_by_itself_then_its_ancestors_then_the_mean() {
        let mut steps = ViewSteps::new(20.0);
        let coarse = TileId::new(4, 3, 5);
        let near = TileId::new(6, 12, 20);
        assert_eq!(steps.of(near), 20.0, "the prior");
        steps.record(&FrameSteps { mean: 30.0, tiles: vec![(coarse, 40.0), (near, 8.0)] });
        assert_eq!(steps.of(near), 8.0);
        assert_eq!(steps.of(coarse), 40.0);
        // A descendant of the coarse tile not drawn: its ancestor's steps;
        // through the near one, the near one's.
        assert_eq!(steps.of(TileId::new(7, 24, 40)), 8.0);
        assert_eq!(steps.of(TileId::new(5, 6, 11)), 40.0);
        // Elsewhere, and above both: the frame's mean.
        assert_eq!(steps.of(TileId::new(4, 0, 0)), 30.0);
        assert_eq!(steps.of(TileId::new(3, 1, 2)), 30.0);
    }

    #[test]
    fn measurements_age_out_and_empty_frames_keep_the_mean() {
        let mut steps = ViewSteps::new(20.0);
        let tile = TileId::new(4, 3, 5);
        steps.record(&FrameSteps { mean: 30.0, tiles: vec![(tile, 40.0)] });
        for _ in 1..MAX_AGE_FRAMES {
            steps.record(&FrameSteps::default());
        }
        assert_eq!(steps.of(tile), 40.0, "drawn within the last {MAX_AGE_FRAMES} frames");
        steps.record(&FrameSteps::default());
        assert_eq!((steps.of(tile), steps.mean()), (30.0, 30.0), "aged out; the mean stays");
        assert!(steps.tiles.is_empty(), "and forgotten");
        steps.record(&FrameSteps { mean: 12.0, tiles: vec![(tile, 11.0)] });
        assert_eq!(steps.of(tile), 11.0);
    }
}
