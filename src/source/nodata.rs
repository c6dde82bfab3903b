//! The nodata policy of a source: fill voids from their neighbours, replace
//! them with a constant, or propagate them as nodata.
//!
//! Filling works on the source's own pixels before any resampling, so it is
//! the same for every tile. Each void takes the inverse-square-distance mean
//! of the nearest valid pixel along each of the 8 compass directions, searched
//! up to `max_distance_px` (the idea of GDAL's `FillNodata`, without its
//! smoothing passes). The value of a void depends only on pixels within that
//! distance, and blocks are computed with that margin, so the result does not
//! depend on block boundaries. Voids farther than the distance from any data
//! stay nodata.

use super::{BlockCache, Blocks, PixelSource, SourceError};
use crate::raster::Raster;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::Arc;

/// What to do with nodata samples.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(tag = "policy", rename_all = "lowercase", deny_unknown_fields)]
pub enum NodataPolicy {
    /// Fill voids from the nearest valid pixels within `max_distance_px`.
    Fill {
        /// Search distance in source pixels.
        #[serde(default = "default_distance")]
        max_distance_px: usize,
    },
    /// Replace nodata with a constant.
    Constant {
        /// The replacement value.
        value: f32,
    },
    /// Keep nodata: tiles carry nodata where the source has none.
    Propagate,
}

fn default_distance() -> usize {
    64
}

impl Default for NodataPolicy {
    fn default() -> Self {
        NodataPolicy::Fill { max_distance_px: default_distance() }
    }
}

/// Puts `pixels` behind the cache with `policy` applied.
pub fn apply(pixels: Arc<dyn PixelSource>, policy: &NodataPolicy, cache: &Arc<BlockCache>) -> Blocks {
    let raw = Blocks::new(pixels, cache);
    match policy {
        NodataPolicy::Propagate => raw,
        _ => Blocks::new(Arc::new(Policy { raw, policy: policy.clone() }), cache),
    }
}

struct Policy {
    raw: Blocks,
    policy: NodataPolicy,
}

impl PixelSource for Policy {
    fn name(&self) -> &Path {
        self.raw.source().name()
    }

    fn size(&self) -> (usize, usize) {
        self.raw.size()
    }

    fn bands(&self) -> usize {
        self.raw.source().bands()
    }

    fn block_size(&self) -> (usize, usize) {
        self.raw.source().block_size()
    }

    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let block = self.block_window(bx, by)?;
        match self.policy {
            NodataPolicy::Constant { value } => {
                Ok(self.raw.read(block)?.into_iter().map(|b| b.map(|v| if v.is_nan() { value } else { v })).collect())
            }
            NodataPolicy::Fill { max_distance_px } => {
                let margin = max_distance_px;
                let around = self.raw.read(block.grown(margin))?;
                Ok(around.iter().map(|band| fill(band, margin, block.width, block.height, max_distance_px)).collect())
            }
            NodataPolicy::Propagate => self.raw.read(block),
        }
    }
}

/// The centre `w × h` of `src` (which has `margin` extra pixels per side), with
/// voids filled.
fn fill(src: &Raster<f32>, margin: usize, w: usize, h: usize, max_distance: usize) -> Raster<f32> {
    const DIRECTIONS: [(i64, i64); 8] = [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)];
    Raster::from_fn(w, h, |x, y| {
        let (cx, cy) = ((x + margin) as i64, (y + margin) as i64);
        let v = src.get(cx as usize, cy as usize);
        if !v.is_nan() {
            return v;
        }
        let (mut sum, mut weight) = (0.0f64, 0.0f64);
        for (dx, dy) in DIRECTIONS {
            let found = (1..=max_distance as i64).find_map(|k| {
                let (sx, sy) = (cx + k * dx, cy + k * dy);
                let inside = sx >= 0 && sy >= 0 && (sx as usize) < src.width() && (sy as usize) < src.height();
                let s = if inside { src.get(sx as usize, sy as usize) } else { f32::NAN };
                (!s.is_nan()).then(|| (s, (k * k * (dx * dx + dy * dy)) as f64))
            });
            if let Some((s, d2)) = found {
                sum += s as f64 / d2;
                weight += 1.0 / d2;
            }
        }
        if weight > 0.0 { (sum / weight) as f32 } else { f32::NAN }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_void_takes_the_inverse_square_mean_of_its_nearest_neighbours() {
        let mut src = Raster::filled(5, 5, 10.0);
        src.set(2, 2, f32::NAN);
        src.set(3, 2, 20.0);
        let out = fill(&src, 0, 5, 5, 4);
        // Seven neighbours of 10 (distances² 1,1,1,2,2,2,2) and one of 20 at distance 1.
        let expect = (20.0 + 10.0 * (3.0 + 4.0 * 0.5)) / (4.0 + 4.0 * 0.5);
        assert!((out.get(2, 2) - expect).abs() < 1e-5);
        let empty = Raster::filled(9, 9, f32::NAN);
        assert!(fill(&empty, 0, 9, 9, 3).all_nodata());
    }

    #[test]
    fn policies_parse_from_toml() {
        let p: NodataPolicy = toml::from_str("policy = \"fill\"\nmax_distance_px = 10").unwrap();
        assert_eq!(p, NodataPolicy::Fill { max_distance_px: 10 });
        let c: NodataPolicy = toml::from_str("policy = \"constant\"\nvalue = 0.0").unwrap();
        assert_eq!(c, NodataPolicy::Constant { value: 0.0 });
        assert!(toml::from_str::<NodataPolicy>("policy = \"guess\"").is_err());
    }
}
