//! The demo map: a 1:50,000 topographic sheet of Val Selva in WGS 84 / UTM
//! 32N at 10 m per pixel (a sheet scanned at about 127 dpi), drawn from the
//! terrain by the rules in [`super::symbols`].
//!
//! A block is drawn from values at its pixel corners, with a margin of one
//! pixel before and two after (the slope reads 3 × 3 pixels, index contours
//! 2 × 2). The sheet is in the terrain's own frame, its corner on the node
//! lattice, so every fourth pixel corner is a terrain node: the terrain comes
//! from one [`terrain::Patch`] per block through [`Patch::sub_grid`]. The
//! slowly varying cover fields are evaluated every 8 corners and
//! interpolated.
//!
//! Invariant: every value a pixel depends on is computed from global sheet
//! indices (mesh points, cover samples, terrain nodes), so a block's pixels
//! do not depend on which blocks were computed before, and a window read
//! across blocks is seamless.

use super::symbols::{self, Corners, Cover};
use super::terrain::{self, Patch};
use crate::raster::Raster;
use crate::source::{BLOCK, Crs, Georef, PixelSource, SourceError};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Sheet extent in UTM 32N, metres: E 576,000–597,000, N 5,127,000–5,146,000
/// covers the demo DEM (9.995–10.255 E, 46.295–46.455 N is E 576,635–596,378,
/// N 5,127,306–5,145,369) with 300 m to spare.
const WEST_M: f64 = 576_000.0;
const NORTH_M: f64 = 5_146_000.0;
/// Pixel size, metres.
const PIXEL_M: f64 = 10.0;
/// Columns: 21 km.
pub const COLS: usize = 2100;
/// Rows: 19 km.
pub const ROWS: usize = 1900;
/// Cover sampling step, corners (80 m: the finest cover noise, the 400 m
/// ragged tree line, gets 5 samples a wavelength, and trails are drawn as
/// polylines of 80 m segments, as on a real sheet).
const COVER_STEP: i64 = 8;

/// The map as a three-band (R, G, B) pixel source, values 0–255.
pub struct MapSource {
    name: PathBuf,
    utm: Arc<Crs>,
}

impl MapSource {
    /// The demo map.
    pub fn new() -> Result<MapSource, SourceError> {
        let name = PathBuf::from("demo: Val Selva 1:50,000 map");
        let utm =
            Crs::from_epsg(terrain::FRAME_EPSG).map_err(|source| SourceError::Crs { path: name.clone(), source })?;
        Ok(MapSource { name, utm: Arc::new(utm) })
    }

    /// Where the map's pixels are.
    pub fn georef(&self) -> Georef {
        Georef {
            crs: self.utm.clone(),
            x0: WEST_M + 0.5 * PIXEL_M,
            y0: NORTH_M - 0.5 * PIXEL_M,
            dx: PIXEL_M,
            dy: -PIXEL_M,
            overhang: 0.5,
        }
    }

    /// Pixels `(c0 .. c0 + w, r0 .. r0 + h)` of the sheet as R, G, B rasters.
    /// Any window gives the same pixels as the blocks it overlaps.
    pub fn render(&self, c0: i64, r0: i64, w: usize, h: usize) -> Vec<Raster<f32>> {
        let corners = self.corners(c0 - 1, r0 - 1, w + 3, h + 3);
        let mut bands = [vec![0.0f32; w * h], vec![0.0f32; w * h], vec![0.0f32; w * h]];
        for r in 0..h {
            for c in 0..w {
                let (col, row) = ((c0 + c as i64).max(0) as usize, (r0 + r as i64).max(0) as usize);
                let rgb = symbols::draw(&corners, c + 1, r + 1, col, row);
                for (band, v) in bands.iter_mut().zip(rgb) {
                    band[r * w + c] = f32::from(v);
                }
            }
        }
        bands.into_iter().filter_map(|b| Raster::from_vec(w, h, b)).collect()
    }

    /// Terrain and cover at sheet corners `(gx0 .. gx0 + w, gy0 .. gy0 + h)`;
    /// corner `(gx, gy)` is the north-west corner of pixel `(gx, gy)`.
    fn corners(&self, gx0: i64, gy0: i64, w: usize, h: usize) -> Corners {
        let (x0, y0) = corner_m(gx0, gy0);
        let (x1, y1) = corner_m(gx0 + w as i64 - 1, gy0 + h as i64 - 1);
        let patch = Patch::covering(x0, y1, x1, y0);
        let cover = CoverSamples::new(gx0, gy0, w as i64, h as i64);
        let mut out = Corners::with_capacity(w, h);
        // Corner (gx, gy) is quarter node (gx + QX, QY − gy) of the terrain.
        let mut row = (usize::MAX, Vec::new());
        patch.sub_grid(gx0 + QX, QY - gy0, w, h, |i, j, g| {
            if row.0 != j {
                row = (j, cover.row(gy0 + j as i64));
            }
            out.push(g, cover.at(&row.1, gx0 + i as i64));
        });
        out
    }
}

/// The sheet's north-west corner in quarter nodes of the terrain frame.
const QX: i64 = ((WEST_M - terrain::ORIGIN_E_M) / PIXEL_M) as i64;
const QY: i64 = ((NORTH_M - terrain::ORIGIN_N_M) / PIXEL_M) as i64;

/// Terrain frame position of sheet corner `(gx, gy)`, metres.
fn corner_m(gx: i64, gy: i64) -> (f64, f64) {
    terrain::local_from_utm(WEST_M + gx as f64 * PIXEL_M, NORTH_M - gy as f64 * PIXEL_M)
}

impl PixelSource for MapSource {
    fn name(&self) -> &Path {
        &self.name
    }

    fn size(&self) -> (usize, usize) {
        (COLS, ROWS)
    }

    fn bands(&self) -> usize {
        3
    }

    fn block_size(&self) -> (usize, usize) {
        (BLOCK, BLOCK)
    }

    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let (c0, r0) = (bx * BLOCK, by * BLOCK);
        if c0 >= COLS || r0 >= ROWS {
            return Err(SourceError::Malformed {
                path: self.name.clone(),
                problem: format!("block ({bx}, {by}) is outside the {COLS}×{ROWS} map"),
            });
        }
        Ok(self.render(c0 as i64, r0 as i64, BLOCK.min(COLS - c0), BLOCK.min(ROWS - r0)))
    }
}

/// Cover fields every [`COVER_STEP`] sheet corners, bilinear in between.
struct CoverSamples {
    kx0: i64,
    ky0: i64,
    cols: usize,
    samples: Vec<Cover>,
}

impl CoverSamples {
    fn new(gx0: i64, gy0: i64, w: i64, h: i64) -> CoverSamples {
        let (kx0, ky0) = (gx0.div_euclid(COVER_STEP), gy0.div_euclid(COVER_STEP));
        let (kx1, ky1) = ((gx0 + w).div_euclid(COVER_STEP) + 1, (gy0 + h).div_euclid(COVER_STEP) + 1);
        let cols = (kx1 - kx0 + 1) as usize;
        let mut samples = Vec::with_capacity(cols * (ky1 - ky0 + 1) as usize);
        for ky in ky0..=ky1 {
            for kx in kx0..=kx1 {
                let (x, y) = corner_m(kx * COVER_STEP, ky * COVER_STEP);
                samples.push(symbols::cover(x, y));
            }
        }
        CoverSamples { kx0, ky0, cols, samples }
    }

    /// The samples of one corner row, interpolated along y (interpolate
    /// along x with [`CoverSamples::at`]).
    fn row(&self, gy: i64) -> Vec<Cover> {
        let ky = gy.div_euclid(COVER_STEP);
        let u = (gy - ky * COVER_STEP) as f64 / COVER_STEP as f64;
        let top = &self.samples[(ky - self.ky0) as usize * self.cols..][..self.cols];
        let bottom = &self.samples[(ky - self.ky0 + 1) as usize * self.cols..][..self.cols];
        top.iter().zip(bottom).map(|(a, b)| a.lerp(b, u)).collect()
    }

    /// Cover at corner column `gx` of a row from [`CoverSamples::row`].
    fn at(&self, row: &[Cover], gx: i64) -> Cover {
        let kx = gx.div_euclid(COVER_STEP);
        let t = (gx - kx * COVER_STEP) as f64 / COVER_STEP as f64;
        let i = (kx - self.kx0) as usize;
        row[i].lerp(&row[i + 1], t)
    }
}
