//! The demo DEM: [`terrain::ground`] sampled like a 1″ global DEM
//! (Copernicus GLO-30 or SRTM-1): EPSG:4326, one arc-second area pixels,
//! float heights, north up.
//!
//! It covers [`super::BBOX`] plus 18″ (≈ 550 m east–west, 390 m north–south)
//! on every side, so tiles at the region's edge have data under their halos.
//! Every edge falls on a whole arc-second, so pixel centres sit on the
//! half-arc-second lattice exactly as in a real 1″ tile.

use super::terrain;
use crate::raster::Raster;
use crate::source::{BLOCK, Crs, Georef, PixelSource, SourceError};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Arc-seconds per degree.
const ARCSEC_PER_DEG: f64 = 3600.0;
/// Margin around the region box, arc-seconds.
const MARGIN_ARCSEC: i64 = 18;
/// West edge: 10.00° E less the margin.
const WEST_ARCSEC: i64 = 10 * 3600 - MARGIN_ARCSEC;
/// North edge: 46.45° N (167,220″) plus the margin.
const NORTH_ARCSEC: i64 = 167_220 + MARGIN_ARCSEC;
/// Columns: 0.25° (900″) plus both margins.
pub const COLS: usize = 900 + 2 * MARGIN_ARCSEC as usize;
/// Rows: 0.15° (540″) plus both margins.
pub const ROWS: usize = 540 + 2 * MARGIN_ARCSEC as usize;

/// Where the DEM's pixels are.
pub fn georef() -> Georef {
    Georef {
        crs: Arc::new(Crs::wgs84()),
        x0: (WEST_ARCSEC as f64 + 0.5) / ARCSEC_PER_DEG,
        y0: (NORTH_ARCSEC as f64 - 0.5) / ARCSEC_PER_DEG,
        dx: 1.0 / ARCSEC_PER_DEG,
        dy: -1.0 / ARCSEC_PER_DEG,
        overhang: 0.5,
    }
}

/// The DEM as a pixel source (one band, metres).
pub struct DemSource {
    name: PathBuf,
    georef: Georef,
}

impl DemSource {
    /// The demo DEM.
    pub fn new() -> DemSource {
        DemSource { name: PathBuf::from("demo: Val Selva DEM, 1″"), georef: georef() }
    }
}

impl Default for DemSource {
    fn default() -> Self {
        DemSource::new()
    }
}

impl PixelSource for DemSource {
    fn name(&self) -> &Path {
        &self.name
    }

    fn size(&self) -> (usize, usize) {
        (COLS, ROWS)
    }

    fn bands(&self) -> usize {
        1
    }

    fn block_size(&self) -> (usize, usize) {
        (BLOCK, BLOCK)
    }

    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let b = self.block_window(bx, by)?;
        let (c0, r0, w, h) = (b.x as usize, b.y as usize, b.width, b.height);
        let g = &self.georef;
        // The local frame is linear in lon and lat: convert columns and rows once.
        let xs: Vec<f64> = (0..w).map(|c| terrain::local_m(g.x0 + (c0 + c) as f64 * g.dx, 0.0).0).collect();
        let ys: Vec<f64> = (0..h).map(|r| terrain::local_m(0.0, g.y0 + (r0 + r) as f64 * g.dy).1).collect();
        Ok(vec![Raster::from_fn(w, h, |c, r| terrain::ground(xs[c], ys[r]).height_m as f32)])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demo::BBOX;

    #[test]
    fn the_dem_covers_the_region_on_whole_arc_seconds() {
        let g = georef();
        let west = g.x0 - 0.5 * g.dx;
        let north = g.y0 - 0.5 * g.dy;
        let east = west + COLS as f64 * g.dx;
        let south = north + ROWS as f64 * g.dy;
        assert!(west < BBOX.west && east > BBOX.east && south < BBOX.south && north > BBOX.north);
        for edge in [west, east, south, north] {
            let arcsec = edge * ARCSEC_PER_DEG;
            assert!((arcsec - arcsec.round()).abs() < 1e-6, "{edge}");
        }
        assert_eq!(DemSource::new().size(), (936, 576));
    }

    #[test]
    fn edge_blocks_are_smaller_and_heights_plausible() {
        let dem = DemSource::new();
        let last = dem.read_block(3, 2).unwrap();
        assert_eq!((last[0].width(), last[0].height()), (936 - 768, 576 - 512));
        assert!(dem.read_block(4, 0).is_err());
        let (lo, hi) = last[0].min_max().unwrap();
        assert!(lo >= 700.0 && hi <= 3700.0, "{lo} {hi}");
    }
}
