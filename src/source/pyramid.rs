//! Overviews: each level halves the resolution of the one below, computed
//! lazily block by block (like GDAL overviews, but derived on demand).
//!
//! Coarse tiles read the overview whose pixels are just finer than their
//! sample spacing, so a level-0 tile neither reads a whole file nor aliases
//! ("at coarse tile levels the proxy is filtered to the tile's sample spacing",
//! `../shared/DESIGN.md`; the same holds for the DEM and the cover).

use super::{BLOCK, Blocks, PixelSource, SourceError};
use crate::raster::{Raster, Window};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How four pixels become one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reducer {
    /// Mean of the valid pixels (continuous fields: heights, cover).
    Mean,
    /// The north-west pixel (classes, which must never be interpolated).
    Decimate,
}

/// One overview level over a finer level.
pub struct Overview {
    finer: Blocks,
    reducers: Arc<[Reducer]>,
    name: PathBuf,
}

impl Overview {
    /// The level above `finer`; band `b` uses `reducers[b]` (the last one for
    /// bands beyond the list).
    pub fn new(finer: Blocks, reducers: Arc<[Reducer]>, level: usize) -> Overview {
        let name = PathBuf::from(format!("{} (overview {level})", finer.source().name().display()));
        Overview { finer, reducers, name }
    }
}

impl PixelSource for Overview {
    fn name(&self) -> &Path {
        &self.name
    }

    fn size(&self) -> (usize, usize) {
        let (w, h) = self.finer.size();
        (w.div_ceil(2), h.div_ceil(2))
    }

    fn bands(&self) -> usize {
        self.finer.source().bands()
    }

    fn block_size(&self) -> (usize, usize) {
        (BLOCK, BLOCK)
    }

    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let b = self.block_window(bx, by)?;
        let (bw, bh) = (b.width, b.height);
        let fine = self.finer.read(Window::new(2 * b.x, 2 * b.y, 2 * bw, 2 * bh))?;
        Ok(fine.iter().enumerate().map(|(b, band)| reduce(band, bw, bh, reducer_of(&self.reducers, b))).collect())
    }
}

/// The reducer of band `band` among `reducers` (the last one for bands
/// beyond the list; the mean for none).
pub fn reducer_of(reducers: &[Reducer], band: usize) -> Reducer {
    reducers.get(band).or(reducers.last()).copied().unwrap_or(Reducer::Mean)
}

/// For a decimated band, where its overview pixels of level `level` lie,
/// in their own pixels, from where [`level_map`] places them: at their
/// blocks' north-west pixels, `(scale − 1) / 2` base pixels north and west
/// of the centres; `None` for a mean, which lies at its block's centre.
pub fn decimated_offset_px(reducer: Reducer, level: usize) -> Option<f64> {
    let scale = (1u64 << level) as f64;
    (reducer == Reducer::Decimate).then(|| -(scale - 1.0) / (2.0 * scale))
}

/// Base pixel coordinate `p` is overview coordinate `(p - shift) / scale`
/// (`(scale, shift)`): each overview pixel at its block's centre.
pub fn level_map(level: usize) -> (f64, f64) {
    let scale = (1u64 << level) as f64;
    (scale, (scale - 1.0) / 2.0)
}

fn reduce(fine: &Raster<f32>, w: usize, h: usize, reducer: Reducer) -> Raster<f32> {
    Raster::from_fn(w, h, |x, y| {
        let quad = [
            fine.get(2 * x, 2 * y),
            fine.get(2 * x + 1, 2 * y),
            fine.get(2 * x, 2 * y + 1),
            fine.get(2 * x + 1, 2 * y + 1),
        ];
        match reducer {
            Reducer::Decimate => quad[0],
            Reducer::Mean => {
                let (sum, n) = quad.iter().filter(|v| !v.is_nan()).fold((0.0f32, 0u8), |(s, n), &v| (s + v, n + 1));
                if n == 0 { f32::NAN } else { sum / n as f32 }
            }
        }
    })
}

/// Level 0 is `base`; each further level halves it, until a level fits in
/// one block.
pub fn build(base: Blocks, reducers: &[Reducer], cache: &Arc<super::BlockCache>) -> Vec<Blocks> {
    let reducers: Arc<[Reducer]> = reducers.into();
    let mut levels = vec![base];
    loop {
        let (w, h) = levels[levels.len() - 1].size();
        if w <= BLOCK && h <= BLOCK {
            return levels;
        }
        let top = levels[levels.len() - 1].clone();
        levels.push(Blocks::new(Arc::new(Overview::new(top, reducers.clone(), levels.len())), cache));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::BlockCache;
    use crate::source::blocks::tests::Counting;
    use std::sync::atomic::AtomicUsize;

    #[test]
    fn overviews_average_and_decimate() {
        let cache = BlockCache::new(1 << 24);
        let src = Arc::new(Counting { size: (600, 300), block: (100, 100), reads: AtomicUsize::new(0) });
        let levels = build(Blocks::new(src, &cache), &[Reducer::Mean], &cache);
        assert_eq!(levels.len(), 3);
        assert_eq!(levels[1].size(), (300, 150));
        assert_eq!(levels[2].size(), (150, 75));
        let v = levels[1].read_band(Window::new(3, 2, 1, 1), 0).unwrap().get(0, 0);
        assert_eq!(v, (6.0 + 7.0 + 6.0 + 7.0 + 4000.0 * 2.0 + 5000.0 * 2.0) / 4.0);
        let dec = build(levels[0].clone(), &[Reducer::Decimate], &cache);
        assert_eq!(dec[2].read_band(Window::new(1, 1, 1, 1), 0).unwrap().get(0, 0), 4.0 + 4000.0);
    }
}
