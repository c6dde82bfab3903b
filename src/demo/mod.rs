//! The embedded demo region, Val Selva: a fictional alpine valley used when
//! no configuration is given, so that every command runs anywhere with no
//! data, and every pipeline stage has something to do.
//!
//! It is built like a real data set: a 1″ DEM in EPSG:4326 ([`dem`], like
//! SRTM-1) and a 1:50,000 topographic map sheet in UTM 32N at 10 m per pixel
//! ([`map`]) whose forest areas are crossed by contour lines and paths, so the
//! cover needs the colour key, the close and the blur, and the map needs
//! reprojection. Both are drawn from one continuous terrain ([`terrain`]).

pub mod dem;
pub mod map;
pub mod terrain;

#[cfg(test)]
mod preview;

pub use map::palette;

use crate::source::{Georef, PixelSource, SourceError};
use std::sync::Arc;

/// The region's name.
pub const NAME: &str = "Sylva demo (Val Selva)";

/// The region's lat/lon box, W,S,E,N.
pub const BBOX: crate::grid::BBox = crate::grid::BBox { west: 10.0, south: 46.30, east: 10.25, north: 46.45 };

/// The demo's sources.
pub struct DemoSources {
    /// The 1″ DEM.
    pub dem: Arc<dyn PixelSource>,
    /// Where the DEM's pixels are.
    pub dem_georef: Georef,
    /// The topographic map (R, G, B).
    pub map: Arc<dyn PixelSource>,
    /// Where the map's pixels are.
    pub map_georef: Georef,
}

/// The demo DEM and map.
pub fn sources() -> Result<DemoSources, SourceError> {
    let map = map::MapSource::new()?;
    let map_georef = map.georef();
    Ok(DemoSources { dem: Arc::new(dem::DemSource::new()), dem_georef: dem::georef(), map: Arc::new(map), map_georef })
}
