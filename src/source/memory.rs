//! A source held in memory: for rasters made by code (synthetic test scenes,
//! the extreme cases) and for callers that already have pixels.

use super::{BLOCK, PixelSource, SourceError};
use crate::raster::Raster;
use std::path::{Path, PathBuf};

/// Bands of equal size in memory.
pub struct MemorySource {
    name: PathBuf,
    bands: Vec<Raster<f32>>,
}

impl MemorySource {
    /// A source named `name` (for messages) over `bands`; `None` if the bands
    /// differ in size or there are none.
    pub fn new(name: &str, bands: Vec<Raster<f32>>) -> Option<MemorySource> {
        let first = bands.first()?;
        let same = bands.iter().all(|b| b.width() == first.width() && b.height() == first.height());
        (same && first.width() > 0 && first.height() > 0).then(|| MemorySource { name: PathBuf::from(name), bands })
    }
}

impl PixelSource for MemorySource {
    fn name(&self) -> &Path {
        &self.name
    }

    fn size(&self) -> (usize, usize) {
        (self.bands[0].width(), self.bands[0].height())
    }

    fn bands(&self) -> usize {
        self.bands.len()
    }

    fn block_size(&self) -> (usize, usize) {
        (BLOCK, BLOCK)
    }

    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let window = self.block_window(bx, by)?;
        Ok(self.bands.iter().map(|b| b.crop(window, f32::NAN)).collect())
    }
}
