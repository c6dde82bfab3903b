//! Raster sources: files (GeoTIFF, SRTM `.hgt`), procedural rasters and rasters
//! derived from others (nodata fill, vegetation cover, overviews), all read by
//! block through one bounded in-memory cache.
//!
//! A [`PixelSource`] knows only pixels: it computes one block at a time. A
//! [`Blocks`] reader puts it behind the shared [`BlockCache`] and assembles any
//! window from cached blocks, so no request re-reads a whole file and a block is
//! computed once however many tiles need it. A [`GeoRaster`] adds
//! georeferencing and an overview pyramid and evaluates the source on a sample
//! grid.
//!
//! Invariant: a block's content depends only on the source and the block
//! index, never on who asked first, so windows assembled from blocks are
//! seamless.

pub mod blocks;
pub mod crs;
pub mod georaster;
pub mod geotiff;
pub mod hgt;
pub mod las;
#[cfg(feature = "http")]
pub mod link;
pub mod memory;
pub mod nodata;
mod palette;
pub mod proxy;
pub mod pyramid;
#[cfg(feature = "http")]
pub mod remote;
pub mod vertical;

pub use blocks::{BlockCache, Blocks};
pub use crs::{Crs, CrsError};
pub use georaster::{Footprint, GeoRaster, Georef};
pub use nodata::NodataPolicy;
pub use pyramid::Reducer;

use crate::raster::{Raster, Window};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use thiserror::Error;

/// Why a source cannot be opened or read. Every variant names the source.
#[derive(Debug, Error)]
pub enum SourceError {
    /// The file is missing or unreadable.
    #[error("{path}: cannot open: {source}")]
    Open {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is readable but malformed or truncated.
    #[error("{path}: {problem}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A valid file that uses a feature Sylva does not read.
    #[error("{path}: unsupported: {what}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// Which feature.
        what: String,
    },
    /// An upstream server failed or answered nonsense.
    #[error("upstream {url}: {problem}")]
    Upstream {
        /// The request.
        url: String,
        /// What went wrong.
        problem: String,
    },
    /// The file's coordinate reference system is unusable.
    #[error("{path}: {source}")]
    Crs {
        /// The file.
        path: PathBuf,
        /// The CRS problem.
        source: CrsError,
    },
}

/// A raster that can compute any of its blocks (all bands at once).
pub trait PixelSource: Send + Sync {
    /// A name for messages: the file path or a description.
    fn name(&self) -> &Path;
    /// Width and height in pixels.
    fn size(&self) -> (usize, usize);
    /// Number of bands.
    fn bands(&self) -> usize;
    /// Width and height of a block (blocks at the right and bottom edges may be
    /// smaller).
    fn block_size(&self) -> (usize, usize);
    /// The pixels of block `(bx, by)`, one raster per band; nodata is NaN.
    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError>;

    /// The pixels block `(bx, by)` covers: a full block, or what is left of
    /// one at the right and bottom edges. An error for a block past the end.
    fn block_window(&self, bx: usize, by: usize) -> Result<Window, SourceError> {
        let ((w, h), (bw, bh)) = (self.size(), self.block_size());
        let (x0, y0) = (bx * bw, by * bh);
        if x0 >= w || y0 >= h {
            return Err(SourceError::Malformed {
                path: self.name().to_path_buf(),
                problem: format!("block ({bx}, {by}) is outside the {w}×{h} raster"),
            });
        }
        Ok(Window::new(x0 as i64, y0 as i64, bw.min(w - x0), bh.min(h - y0)))
    }
}

/// Side of the blocks of derived and in-memory sources: 256² f32 is 256 KiB a
/// band, small enough that a tile touches few more pixels than it needs.
pub const BLOCK: usize = 256;

/// How to open a raster file.
#[derive(Clone, Debug, Default)]
pub struct OpenOptions {
    /// EPSG code to use instead of the file's own CRS.
    pub crs: Option<u32>,
    /// What to do with the file's nodata samples.
    pub nodata: NodataPolicy,
    /// How overviews combine pixels (classes must decimate).
    pub classes: bool,
}

/// Opens a raster file by its extension: `.tif`/`.tiff` (GeoTIFF) or `.hgt`
/// (SRTM), applies the nodata policy and adds overviews.
pub fn open_file(path: &Path, options: &OpenOptions, cache: &Arc<BlockCache>) -> Result<GeoRaster, SourceError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let (pixels, georef) = match ext.as_deref() {
        Some("tif" | "tiff") => geotiff::open(path, options.crs)?,
        Some("hgt") => hgt::open(path)?,
        _ => {
            return Err(SourceError::Unsupported {
                path: path.to_path_buf(),
                what: "file type (expected .tif, .tiff or .hgt)".into(),
            });
        }
    };
    let reducer = if options.classes { Reducer::Decimate } else { Reducer::Mean };
    on_the_globe(path, GeoRaster::new(nodata::apply(pixels, &options.nodata, cache), georef, &[reducer], cache))
}

/// The raster, if its data lies on the globe: a file whose coordinates are
/// read in the wrong CRS (metres as degrees, say, by a wrong `crs =` of the
/// configuration) is refused here, naming its CRS, rather than giving a
/// region off the globe that every request misses; so is one wider than the
/// globe.
fn on_the_globe(path: &Path, raster: GeoRaster) -> Result<GeoRaster, SourceError> {
    let (s, slack) = (raster.bounds(), raster.georef().pixel_deg());
    let lat =
        (-90.0 - slack..=90.0 + slack).contains(&s.min_lat) && (-90.0 - slack..=90.0 + slack).contains(&s.max_lat);
    let lon = (-540.0..=540.0).contains(&s.min_lon) && (-540.0..=540.0).contains(&s.max_lon);
    let (width, crs) = (s.max_lon - s.min_lon, raster.georef().crs.epsg());
    let problem = if !(lat && lon && s.min_lat < s.max_lat && s.min_lon < s.max_lon) {
        format!(
            "read in EPSG:{crs} its data lies at longitudes {:.6} to {:.6}, latitudes {:.6} to {:.6}, off the globe: \
             is that its CRS? (`crs = \"EPSG:code\"` in the configuration names another)",
            s.min_lon, s.max_lon, s.min_lat, s.max_lat
        )
    } else if width > 360.0 + slack {
        format!("its data spans {width:.6}° of longitude ({:.6} to {:.6}), more than the globe", s.min_lon, s.max_lon)
    } else {
        return Ok(raster);
    };
    Err(SourceError::Malformed { path: path.to_path_buf(), problem })
}
