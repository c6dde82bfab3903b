//! Where the client's tiles come from: the CEM pipeline in process
//! ([`RegionSource`]), or a `sylva serve` over HTTP (`client::http::HttpSource`,
//! feature `http`). Both deliver the same [`TilePayload`]: CEM, ground, surface
//! classes and unshaded map colour with a halo.

use super::tile::TilePayload;
use crate::cem::{self, Layer};
use crate::encode::relief::base_colours;
use crate::grid::{BBox, TileGrid, TileId};
use crate::produce::{self, ProduceError};
use crate::region::Region;
use std::sync::Arc;

/// Why a tile could not be fetched.
#[derive(Debug, thiserror::Error)]
pub enum FetchError {
    /// The pipeline failed on a source.
    #[error("tile {id}: {source}")]
    Produce {
        /// The tile.
        id: TileId,
        /// What failed.
        source: ProduceError,
    },
    /// The server failed or answered something unusable.
    #[error("tile {id} from {url}: {reason}")]
    Http {
        /// The tile.
        id: TileId,
        /// The request.
        url: String,
        /// What went wrong.
        reason: String,
    },
}

/// A source of tiles on one grid.
pub trait TileSource: Send + Sync {
    /// The tile grid.
    fn grid(&self) -> TileGrid;
    /// The area with data.
    fn bounds(&self) -> BBox;
    /// One tile with `halo`; `None` where the tile has no data at all.
    fn fetch(&self, id: TileId, halo: usize) -> Result<Option<TilePayload>, FetchError>;
    /// Bytes transferred so far (0 in process).
    fn bytes_fetched(&self) -> u64 {
        0
    }
    /// Why no tile came, where tiles were asked for and every answer was
    /// that there is none (a server's 404s): a flight that drew nothing
    /// says so rather than guess at its camera.
    fn why_no_tile(&self) -> Option<String> {
        None
    }
    /// A one-line description.
    fn describe(&self) -> String;
}

/// Tiles computed by the pipeline in this process.
#[derive(Clone)]
pub struct RegionSource {
    region: Arc<Region>,
}

impl RegionSource {
    /// A source over `region`.
    pub fn new(region: Arc<Region>) -> RegionSource {
        RegionSource { region }
    }
}

impl TileSource for RegionSource {
    fn grid(&self) -> TileGrid {
        self.region.tiles
    }

    fn bounds(&self) -> BBox {
        self.region.bounds
    }

    fn fetch(&self, id: TileId, halo: usize) -> Result<Option<TilePayload>, FetchError> {
        let region = &self.region;
        let err = |source: ProduceError| FetchError::Produce { id, source };
        region.tiles.check(id).map_err(|e| err(e.into()))?;
        let grid = region.tiles.tile_samples(id, halo);
        let products =
            cem::compute(region, &grid, &[Layer::Dem, Layer::Cem, Layer::Surface]).map_err(|e| err(e.into()))?;
        let (Some(dem), Some(cem), Some(surface)) = (products.dem, products.cem, products.surface) else {
            return Ok(None);
        };
        if cem.all_nodata() {
            return Ok(None);
        }
        let map = produce::map_colours(region, &grid).map_err(err)?;
        let colour = base_colours(&surface, map.as_deref());
        Ok(Some(TilePayload {
            id,
            halo,
            cem: cem.into_vec(),
            dem: dem.into_vec(),
            surface: surface.into_vec(),
            colour,
        }))
    }

    fn describe(&self) -> String {
        format!("in process: {}", self.region.describe())
    }
}

/// The tile source of `sylva fly`: a server if given, else the region of a
/// configuration (or the demo).
#[cfg(feature = "http")]
pub fn open(config: Option<&std::path::Path>, server: Option<&str>) -> Result<Box<dyn TileSource>, OpenError> {
    match server {
        Some(url) => Ok(Box::new(super::http::HttpSource::connect(url)?)),
        None => Ok(Box::new(RegionSource::new(Arc::new(crate::config::load(config)?)))),
    }
}

/// Why a tile source could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The configuration is bad.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// The server could not be used.
    #[error("{0}")]
    Server(String),
}
