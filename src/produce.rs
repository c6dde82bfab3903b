//! From a request to encoded bytes: a World Wind tile, or a whole-area build
//! over a box. Used by the command line and the client's in-process tile
//! source; the server and the seeder encode through `server::products`.

use crate::cem::{self, Layer, Stats};
use crate::encode::{self, EncodeError, Encoded, Format};
use crate::grid::{BBox, GridError, SampleGrid, TileId};
use crate::region::Region;
use crate::source::SourceError;
use thiserror::Error;

/// Largest halo, samples (a tile of 513 + 2·512 samples per side).
pub const MAX_HALO: usize = 512;

/// Why a product could not be made, sorted by who is at fault.
#[derive(Debug, Error)]
pub enum ProduceError {
    /// A bad request: no such tile, bad box or size.
    #[error(transparent)]
    Request(#[from] GridError),
    /// A source failed.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// Encoding failed.
    #[error(transparent)]
    Encode(#[from] EncodeError),
}

/// An encoded product with the grid it covers and the pipeline's stats.
#[derive(Debug)]
pub struct Product {
    /// The bytes and quantization.
    pub encoded: Encoded,
    /// The sample grid.
    pub grid: SampleGrid,
    /// Stage runs and times.
    pub stats: Stats,
    /// True when no sample holds data (the area misses the sources' data).
    pub no_data: bool,
}

/// One tile of `layer` with `halo` extra samples per side.
pub fn tile(region: &Region, id: TileId, halo: usize, layer: Layer, format: Format) -> Result<Product, ProduceError> {
    region.tiles.check(id)?;
    if halo > MAX_HALO {
        let n = region.tiles.samples() as usize + 2 * halo;
        return Err(
            GridError::BadSize { width: n, height: n, reason: format!("halo must be at most {MAX_HALO}") }.into()
        );
    }
    grid_product(region, &region.tiles.tile_samples(id, halo), layer, format)
}

/// A whole-area computation of `layer` on the point-registered `width ×
/// height` grid over `bbox` (the reference every tile must match).
pub fn area(
    region: &Region,
    bbox: BBox,
    width: usize,
    height: usize,
    layer: Layer,
    format: Format,
) -> Result<Product, ProduceError> {
    let grid = bbox.checked()?.point_grid(width, height, &region.tiles)?;
    grid_product(region, &grid, layer, format)
}

/// `layer` computed and encoded on any grid.
pub fn grid_product(region: &Region, grid: &SampleGrid, layer: Layer, format: Format) -> Result<Product, ProduceError> {
    let products = cem::compute(region, grid, &[layer])?;
    let samples =
        products.samples(layer).ok_or_else(|| EncodeError(format!("layer {} was not computed", layer.name())))?;
    let no_data = samples.all_nodata();
    let encoded = encode::encode(layer, samples, grid, format, region.heights_16)?;
    Ok(Product { encoded, grid: *grid, stats: products.stats, no_data })
}

/// The region's map colours (R, G, B, 0–255) at the grid's samples, read and
/// projected once for the three bands; `None` without a map or where the
/// grid misses it.
pub fn map_colours(
    region: &Region,
    grid: &SampleGrid,
) -> Result<Option<Vec<crate::raster::Raster<f32>>>, ProduceError> {
    let Some(map) = &region.map else { return Ok(None) };
    let bilinear = crate::raster::resample::Resampling::Bilinear;
    let footprint = map.read(grid, bilinear, 3)?;
    Ok(footprint.map(|f| (0..3).map(|b| f.resample(b, bilinear)).collect()))
}
