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
use crate::raster::{Raster, Window};
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

/// The longest search of [`NodataPolicy::Fill`], source pixels: each block
/// is filled from its pixels and this many around them.
pub const MAX_FILL_DISTANCE_PX: usize = 2048;

impl NodataPolicy {
    /// Why the policy cannot be used, if it cannot.
    pub fn check(&self) -> Result<(), String> {
        match *self {
            NodataPolicy::Fill { max_distance_px } if !(1..=MAX_FILL_DISTANCE_PX).contains(&max_distance_px) => {
                Err(format!("max_distance_px = {max_distance_px}: must be 1 to {MAX_FILL_DISTANCE_PX}"))
            }
            NodataPolicy::Constant { value } if !value.is_finite() => {
                Err(format!("value = {value}: must be a finite height"))
            }
            _ => Ok(()),
        }
    }
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
                // Beyond the raster lies no data to fill from.
                let (w, h) = self.size();
                let around = block.grown(max_distance_px).intersect(&Window::new(0, 0, w, h)).unwrap_or(block);
                let at = ((block.x - around.x) as usize, (block.y - around.y) as usize);
                let bands = self.raw.read(around)?;
                Ok(bands.iter().map(|band| fill(band, at, (block.width, block.height), max_distance_px)).collect())
            }
            NodataPolicy::Propagate => self.raw.read(block),
        }
    }
}

/// The `w × h` window of `src` at `at`, with voids filled from `src`.
fn fill(src: &Raster<f32>, at: (usize, usize), (w, h): (usize, usize), max_distance: usize) -> Raster<f32> {
    const DIRECTIONS: [(i64, i64); 8] = [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)];
    // No search goes past the edge of `src`.
    let max_distance = max_distance.min(src.width().max(src.height()));
    Raster::from_fn(w, h, |x, y| {
        let (cx, cy) = ((x + at.0) as i64, (y + at.1) as i64);
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
        let out = fill(&src, (0, 0), (5, 5), 4);
        // Seven neighbours of 10 (distances² 1,1,1,2,2,2,2) and one of 20 at distance 1.
        let expect = (20.0 + 10.0 * (3.0 + 4.0 * 0.5)) / (4.0 + 4.0 * 0.5);
        assert!((out.get(2, 2) - expect).abs() < 1e-5);
        let empty = Raster::filled(9, 9, f32::NAN);
        assert!(fill(&empty, (0, 0), (9, 9), 3).all_nodata());
    }

    #[test]
    fn blocks_are_filled_as_the_whole_raster_and_read_no_more_than_it() {
        // 300 × 280 pixels, four blocks, a void across their corner.
        let mut src = Raster::from_fn(300, 280, |x, y| (x as f32 * 0.1).sin() * 50.0 + y as f32);
        for (x, y) in (230..290).flat_map(|x| (240..270).map(move |y| (x, y))) {
            src.set(x, y, f32::NAN);
        }
        let memory: Arc<dyn PixelSource> =
            Arc::new(super::super::memory::MemorySource::new("holes", vec![src.clone()]).unwrap());
        let cache = BlockCache::new(64 << 20);
        // Regression: the distance grew every block's read by itself, so
        // 10⁹ asked for exabytes.
        for distance in [40, MAX_FILL_DISTANCE_PX, 1_000_000_000] {
            let filled = apply(memory.clone(), &NodataPolicy::Fill { max_distance_px: distance }, &cache);
            let got = filled.read(Window::new(0, 0, 300, 280)).unwrap().remove(0);
            let whole = fill(&src, (0, 0), (300, 280), distance);
            assert!(got == whole, "distance {distance}: blocks differ from the whole");
            assert_eq!(got.data().iter().filter(|v| v.is_nan()).count(), 0, "distance {distance}");
        }
    }

    #[test]
    fn distances_and_values_that_cannot_fill_are_refused() {
        for (policy, needle) in [
            (NodataPolicy::Fill { max_distance_px: 0 }, "must be 1 to 2048"),
            (NodataPolicy::Fill { max_distance_px: 1_000_000_000 }, "max_distance_px = 1000000000"),
            (NodataPolicy::Constant { value: f32::NAN }, "value = NaN: must be a finite height"),
        ] {
            assert!(policy.check().unwrap_err().contains(needle), "{policy:?}");
        }
        assert!(NodataPolicy::default().check().is_ok() && NodataPolicy::Propagate.check().is_ok());
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
