//! The demo DEM: the terrain ([`terrain`]) sampled like a 1″ global DEM
//! (Copernicus GLO-30 or SRTM-1): EPSG:4326, one arc-second area pixels,
//! float heights, north up.
//!
//! Pixel centres go to the terrain's UTM frame through the projection exactly
//! every `MESH_PX` pixels (global indices, so blocks agree) and bilinearly
//! between: over 16″ the projection is linear to far below a millimetre.
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

/// Projection mesh spacing, pixels.
const MESH_PX: usize = 16;

/// The DEM as a pixel source (one band, metres).
pub struct DemSource {
    name: PathBuf,
    georef: Georef,
    utm: Crs,
}

impl DemSource {
    /// The demo DEM; fails only if the terrain frame's projection cannot be
    /// set up.
    pub fn new() -> Result<DemSource, SourceError> {
        let name = PathBuf::from("demo: Val Selva DEM, 1″");
        let utm =
            Crs::from_epsg(terrain::FRAME_EPSG).map_err(|source| SourceError::Crs { path: name.clone(), source })?;
        Ok(DemSource { name, georef: georef(), utm })
    }

    /// Terrain frame position of the centre of pixel `(col, row)`, for
    /// `col` and `row` multiples of [`MESH_PX`] (NaN if the projection fails).
    fn mesh_point(&self, col: usize, row: usize) -> (f64, f64) {
        let g = &self.georef;
        let (lon, lat) = (g.x0 + col as f64 * g.dx, g.y0 + row as f64 * g.dy);
        self.utm.from_lon_lat(lon, lat).map_or((f64::NAN, f64::NAN), |(e, n)| terrain::local_from_utm(e, n))
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
        // Mesh points from the one at or before the block to the one at or after its end.
        let (m0x, m0y) = (c0 / MESH_PX, r0 / MESH_PX);
        let (mw, mh) = ((c0 + w - 1) / MESH_PX - m0x + 2, (r0 + h - 1) / MESH_PX - m0y + 2);
        let mesh = Raster::from_fn(mw, mh, |i, j| self.mesh_point((m0x + i) * MESH_PX, (m0y + j) * MESH_PX));
        let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
        for &(x, y) in mesh.data() {
            (lo, hi) = ((lo.0.min(x), lo.1.min(y)), (hi.0.max(x), hi.1.max(y)));
        }
        let patch = terrain::Patch::covering(lo.0, lo.1, hi.0, hi.1);
        let heights = Raster::from_fn(w, h, |c, r| {
            let (col, row) = (c0 + c, r0 + r);
            let (i, j) = (col / MESH_PX - m0x, row / MESH_PX - m0y);
            let t = (col % MESH_PX) as f64 / MESH_PX as f64;
            let u = (row % MESH_PX) as f64 / MESH_PX as f64;
            let (a, b, c, d) = (mesh.get(i, j), mesh.get(i + 1, j), mesh.get(i, j + 1), mesh.get(i + 1, j + 1));
            let mix =
                |p: f64, q: f64, r: f64, s: f64| (1.0 - u) * ((1.0 - t) * p + t * q) + u * ((1.0 - t) * r + t * s);
            patch.height_m(mix(a.0, b.0, c.0, d.0), mix(a.1, b.1, c.1, d.1)) as f32
        });
        Ok(vec![heights])
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
        assert_eq!(DemSource::new().unwrap().size(), (936, 576));
    }

    #[test]
    fn edge_blocks_are_smaller_and_heights_plausible() {
        let dem = DemSource::new().unwrap();
        let last = dem.read_block(3, 2).unwrap();
        assert_eq!((last[0].width(), last[0].height()), (936 - 768, 576 - 512));
        assert!(dem.read_block(4, 0).is_err());
        let (lo, hi) = last[0].min_max().unwrap();
        assert!(lo >= 700.0 && hi <= 3700.0, "{lo} {hi}");
    }
}
