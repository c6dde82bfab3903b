//! Stage 5: ray-casting acceleration data, conservative by construction.
//!
//! - **Safety zones** (dissertation 6.4 "Ray Casting Acceleration", after Kolb
//!   et al.): for each sample the maximum height within a square of radius
//!   [`ZONE_NEAR`] and [`ZONE_FAR`] samples. The bilinear surface over the
//!   square `[i−r, i+r]²` never exceeds the samples in it (a bilinear patch
//!   peaks at a corner), so the zone maximum bounds the surface there. The far
//!   zone is the near zone dilated by `32 − 4`: a square dilated by a square
//!   is the larger square, exactly.
//! - **Maximum mipmap**: level 0 holds the maximum of each cell's four corner
//!   samples (a bound on the bilinear patch); each further level the maximum of
//!   2×2 cells below, so a texel bounds every cell beneath it. The exact
//!   hierarchical traversal of the client walks it.
//!
//! Nodata samples (NaN) bound nothing; a zone or cell with only nodata is NaN.

use crate::raster::Raster;
use crate::raster::morphology::dilate_inner;

/// The near safety zone's radius, in samples ("4 and 32 texel safety zones").
pub const ZONE_NEAR: usize = 4;
/// The far safety zone's radius, in samples.
pub const ZONE_FAR: usize = 32;

/// The margin the zones need: [`ZONE_FAR`] for the far zone, else
/// [`ZONE_NEAR`] for the near one.
pub fn margin(near: bool, far: bool) -> usize {
    if far {
        ZONE_FAR
    } else if near {
        ZONE_NEAR
    } else {
        0
    }
}

/// The requested safety zones of the centre of `cem`, which carries
/// [`margin`] extra samples on every side: `(near, far)`, each the size of the
/// centre. With both, the far zone is the near one dilated further. Only the
/// squares that fit in `cem` are evaluated, so no zone reads past its data.
pub fn safety_zones(cem: &Raster<f32>, near: bool, far: bool) -> (Option<Raster<f32>>, Option<Raster<f32>>) {
    match (near, far) {
        (true, true) => {
            let n = dilate_inner(cem, ZONE_NEAR);
            let f = dilate_inner(&n, ZONE_FAR - ZONE_NEAR);
            let m = (ZONE_FAR - ZONE_NEAR) as i64;
            let inner = crate::raster::Window::new(m, m, f.width(), f.height());
            (Some(n.crop(inner, f32::NAN)), Some(f))
        }
        (false, true) => (None, Some(dilate_inner(cem, ZONE_FAR))),
        (true, false) => (Some(dilate_inner(cem, ZONE_NEAR)), None),
        (false, false) => (None, None),
    }
}

/// A maximum mipmap over the cells of a height grid.
#[derive(Clone, Debug)]
pub struct MaxMipmap {
    levels: Vec<Raster<f32>>,
}

impl MaxMipmap {
    /// Builds the mipmap of `heights` (`w × h` samples, `(w−1) × (h−1)`
    /// cells); the top level is a single texel.
    pub fn build(heights: &Raster<f32>) -> MaxMipmap {
        let (w, h) = (heights.width().saturating_sub(1).max(1), heights.height().saturating_sub(1).max(1));
        let tap = |x: usize, y: usize| heights.get(x.min(heights.width() - 1), y.min(heights.height() - 1));
        let base = Raster::from_fn(w, h, |x, y| tap(x, y).max(tap(x + 1, y)).max(tap(x, y + 1)).max(tap(x + 1, y + 1)));
        let mut levels = vec![base];
        while let Some(top) = levels.last().filter(|t| t.width() > 1 || t.height() > 1) {
            let (tw, th) = (top.width(), top.height());
            let at = |x: usize, y: usize| if x < tw && y < th { top.get(x, y) } else { f32::NAN };
            let next = Raster::from_fn(tw.div_ceil(2), th.div_ceil(2), |x, y| {
                at(2 * x, 2 * y).max(at(2 * x + 1, 2 * y)).max(at(2 * x, 2 * y + 1)).max(at(2 * x + 1, 2 * y + 1))
            });
            levels.push(next);
        }
        MaxMipmap { levels }
    }

    /// Number of levels (level 0 = cells).
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// The raster of one level.
    pub fn level(&self, level: usize) -> &Raster<f32> {
        &self.levels[level]
    }

    /// Upper bound of the surface over the cells that texel `(x, y)` of
    /// `level` covers (cells `x·2ˡ .. (x+1)·2ˡ`).
    pub fn bound(&self, level: usize, x: usize, y: usize) -> f32 {
        self.levels[level].get(x, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn terrain(w: usize, h: usize) -> Raster<f32> {
        Raster::from_fn(w, h, |x, y| ((x * 37 + y * 91) % 53) as f32 + if x == 7 { 1000.0 } else { 0.0 })
    }

    #[test]
    fn every_texel_bounds_the_cells_below_it() {
        let heights = terrain(23, 17);
        let mip = MaxMipmap::build(&heights);
        assert_eq!(mip.level(mip.levels() - 1).data().len(), 1);
        for level in 0..mip.levels() {
            let s = 1usize << level;
            for cy in 0..16 {
                for cx in 0..22 {
                    let corners = [
                        heights.get(cx, cy),
                        heights.get(cx + 1, cy),
                        heights.get(cx, cy + 1),
                        heights.get(cx + 1, cy + 1),
                    ];
                    let top = corners.iter().fold(f32::MIN, |a, &b| a.max(b));
                    assert!(mip.bound(level, cx / s, cy / s) >= top);
                }
            }
        }
        // The 1000 m cliff at x = 7 is in the bound of its cells and not beyond.
        assert_eq!(mip.bound(0, 6, 0), mip.bound(0, 6, 0).max(1000.0));
        assert!(mip.bound(0, 8, 0) < 1000.0);
    }

    #[test]
    fn zones_bound_their_squares_and_the_far_zone_equals_a_direct_dilation() {
        let cem = terrain(100, 90);
        let (Some(near), Some(far)) = safety_zones(&cem, true, true) else { panic!("both zones") };
        assert_eq!(safety_zones(&cem, false, true).1.as_ref(), Some(&far));
        assert_eq!((near.width(), near.height()), (36, 26));
        let direct = crate::raster::morphology::dilate(&cem, ZONE_FAR);
        for y in 0..26 {
            for x in 0..36 {
                assert_eq!(far.get(x, y), direct.get(x + 32, y + 32));
                for dy in 0..=8 {
                    for dx in 0..=8 {
                        assert!(near.get(x, y) >= cem.get(x + 28 + dx, y + 28 + dy));
                    }
                }
            }
        }
    }
}
