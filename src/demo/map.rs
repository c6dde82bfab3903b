//! The demo map: a 1:50,000 topographic sheet of Val Selva, drawn from the
//! terrain as a survey office would, in WGS 84 / UTM 32N at 10 m per pixel (a
//! sheet scanned at about 127 dpi).
//!
//! Layers, bottom to top: open land; forest (light green, from 960 m to a
//! ragged tree line near 2,250 m, off slopes steeper than 45°, with meadow
//! clearings); rock (white with grey scree dots, above about 2,600 m or
//! steeper than 48°); water (lake and river fill, a dark shore line, side streams as
//! one-pixel blue lines); brown contours every 20 m (1 px) with index
//! contours every 100 m (2 px), not over water or in cliffs; black paths;
//! the kilometre grid. Lines that cross forest are at most 2 px wide, so the
//! dissertation's close (two 3×3 dilations, then two erosions) bridges them.
//! Colours carry ±3 levels of scanner noise.
//!
//! Each block is drawn from terrain evaluated at its own pixel corners (with
//! a one-pixel margin), so blocks are independent and deterministic.

use super::terrain::{self, Ground};
use crate::noise::{hash2, unit};
use crate::raster::Raster;
use crate::source::{BLOCK, Crs, Georef, PixelSource, SourceError};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The sheet's colours (sRGB).
pub mod palette {
    /// Forest fill.
    pub const FOREST: [u8; 3] = [197, 227, 165];
    /// Open land.
    pub const OPEN: [u8; 3] = [250, 248, 238];
    /// Lake and river fill.
    pub const WATER: [u8; 3] = [160, 205, 240];
    /// Shore lines and streams.
    pub const SHORE: [u8; 3] = [46, 110, 180];
    /// Contour lines.
    pub const CONTOUR: [u8; 3] = [176, 120, 64];
    /// Paths and roads.
    pub const PATH: [u8; 3] = [35, 31, 32];
    /// Bare rock.
    pub const ROCK: [u8; 3] = [242, 242, 240];
    /// Scree dots on rock.
    pub const SCREE: [u8; 3] = [154, 154, 150];
    /// Kilometre grid.
    pub const GRID: [u8; 3] = [90, 110, 160];
}

/// Sheet extent in UTM 32N, metres: covers the demo DEM (9.995–10.255 E,
/// 46.295–46.455 N is E 576,635–596,378, N 5,127,306–5,145,369).
const WEST_M: f64 = 576_000.0;
const NORTH_M: f64 = 5_146_000.0;
/// Pixel size, metres.
const PIXEL_M: f64 = 10.0;
/// Columns and rows: 21 km × 19 km.
pub const COLS: usize = 2100;
/// Rows.
pub const ROWS: usize = 1900;
/// Pixels per kilometre; the sheet's corner is on the kilometre grid, so
/// pixels whose west or north edge is on a grid line draw it.
const KM_PX: usize = 100;
/// Contour interval and index interval, metres.
const CONTOUR_M: f64 = 20.0;
const INDEX_M: f64 = 100.0;
const SEED: u64 = 0x0000_70B0_5EE7;

/// The map as a three-band (R, G, B) pixel source.
pub struct MapSource {
    name: PathBuf,
    utm: Arc<Crs>,
}

impl MapSource {
    /// The demo map.
    pub fn new() -> Result<MapSource, SourceError> {
        let name = PathBuf::from("demo: Val Selva 1:50,000 map");
        let utm = Crs::from_epsg(32632).map_err(|source| SourceError::Crs { path: name.clone(), source })?;
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

    /// Terrain at the corners of the block's pixels, with one pixel of margin:
    /// corner `(i, j)` is the north-west corner of pixel `(c0 − 1 + i, r0 − 1 + j)`.
    ///
    /// The terrain is evaluated exactly at every second corner of the sheet
    /// (global even indices, so blocks agree) and interpolated between: its
    /// finest relief has a 110 m wavelength, and four times fewer
    /// evaluations keep a block near 15 ms.
    fn corners(&self, c0: usize, r0: usize, w: usize, h: usize) -> Raster<Ground> {
        let (gx0, gy0) = (c0 as i64 - 1, r0 as i64 - 1);
        let (kx0, ky0) = (gx0.div_euclid(2), gy0.div_euclid(2));
        let (kw, kh) = ((gx0 + w as i64 + 3).div_euclid(2) - kx0 + 2, (gy0 + h as i64 + 3).div_euclid(2) - ky0 + 2);
        let frame = LocalFrame::new(&self.utm, 2 * kx0, 2 * ky0, 2 * kw, 2 * kh);
        let coarse = Raster::from_fn(kw as usize, kh as usize, |i, j| {
            let (x, y) = frame.at(2 * (kx0 + i as i64), 2 * (ky0 + j as i64));
            terrain::ground(x, y)
        });
        Raster::from_fn(w + 3, h + 3, |i, j| {
            let (gx, gy) = (gx0 + i as i64, gy0 + j as i64);
            let (ci, cj) = ((gx.div_euclid(2) - kx0) as usize, (gy.div_euclid(2) - ky0) as usize);
            let (t, u) = (0.5 * gx.rem_euclid(2) as f64, 0.5 * gy.rem_euclid(2) as f64);
            let top = mix(&coarse.get(ci, cj), &coarse.get(ci + 1, cj), t);
            let bottom = mix(&coarse.get(ci, cj + 1), &coarse.get(ci + 1, cj + 1), t);
            mix(&top, &bottom, u)
        })
    }
}

/// The terrain frame position of sheet corners: exact (through the UTM
/// projection) every [`MESH`] corners of the sheet, bilinear in between
/// (over 160 m the projection is linear to far below a millimetre).
struct LocalFrame {
    kx0: i64,
    ky0: i64,
    cols: usize,
    points: Vec<(f64, f64)>,
}

/// Mesh spacing in corners.
const MESH: i64 = 16;

impl LocalFrame {
    /// The mesh over corners `gx0 .. gx0 + w`, `gy0 .. gy0 + h`.
    fn new(utm: &Crs, gx0: i64, gy0: i64, w: i64, h: i64) -> LocalFrame {
        let (kx0, ky0) = (gx0.div_euclid(MESH), gy0.div_euclid(MESH));
        let (kx1, ky1) = ((gx0 + w).div_euclid(MESH) + 1, (gy0 + h).div_euclid(MESH) + 1);
        let cols = (kx1 - kx0 + 1) as usize;
        let mut points = Vec::with_capacity(cols * (ky1 - ky0 + 1) as usize);
        for ky in ky0..=ky1 {
            for kx in kx0..=kx1 {
                let (e, n) = (WEST_M + (kx * MESH) as f64 * PIXEL_M, NORTH_M - (ky * MESH) as f64 * PIXEL_M);
                points.push(utm.to_lon_lat(e, n).map_or((f64::NAN, f64::NAN), |(lon, lat)| terrain::local_m(lon, lat)));
            }
        }
        LocalFrame { kx0, ky0, cols, points }
    }

    /// Frame position of sheet corner `(gx, gy)`.
    fn at(&self, gx: i64, gy: i64) -> (f64, f64) {
        let (kx, ky) = (gx.div_euclid(MESH), gy.div_euclid(MESH));
        let (t, u) = ((gx - kx * MESH) as f64 / MESH as f64, (gy - ky * MESH) as f64 / MESH as f64);
        let i = (ky - self.ky0) as usize * self.cols + (kx - self.kx0) as usize;
        let (a, b, c, d) =
            (self.points[i], self.points[i + 1], self.points[i + self.cols], self.points[i + self.cols + 1]);
        let mix = |p: f64, q: f64, r: f64, s: f64| (1.0 - u) * ((1.0 - t) * p + t * q) + u * ((1.0 - t) * r + t * s);
        (mix(a.0, b.0, c.0, d.0), mix(a.1, b.1, c.1, d.1))
    }
}

/// Linear interpolation of every field of the terrain record.
fn mix(a: &Ground, b: &Ground, t: f64) -> Ground {
    if t == 0.0 {
        return *a;
    }
    let l = |p: f64, q: f64| p + t * (q - p);
    Ground {
        height_m: l(a.height_m, b.height_m),
        lake_m: l(a.lake_m, b.lake_m),
        river_m: l(a.river_m, b.river_m),
        stream_m: l(a.stream_m, b.stream_m),
        along_m: l(a.along_m, b.along_m),
        across_m: l(a.across_m, b.across_m),
    }
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
        let b = self.block_window(bx, by)?;
        let (c0, r0, w, h) = (b.x as usize, b.y as usize, b.width, b.height);
        let corners = self.corners(c0, r0, w, h);
        let colours = Raster::from_fn(w, h, |c, r| draw(&corners, c + 1, r + 1, c0 + c, r0 + r));
        Ok((0..3).map(|b| colours.map(|rgb| f32::from(rgb[b]))).collect())
    }
}

/// The colour of the pixel whose north-west corner is corner `(i, j)`;
/// `(col, row)` is its place on the sheet.
fn draw(corners: &Raster<Ground>, i: usize, j: usize, col: usize, row: usize) -> [u8; 3] {
    let quad = [corners.get(i, j), corners.get(i + 1, j), corners.get(i, j + 1), corners.get(i + 1, j + 1)];
    let mean = |f: fn(&Ground) -> f64| quad.iter().map(f).sum::<f64>() / 4.0;
    let height = mean(|g| g.height_m);
    let slope_deg = slope(&quad);
    let wet = quad.iter().filter(|g| g.lake_m > 0.0).count();
    let river = mean(|g| g.river_m).abs() < terrain::RIVER_HALF_WIDTH_M;
    let (x, y) = (quad[0].along_m, quad[0].across_m);
    let base = if wet == 4 || river {
        palette::WATER
    } else if rock(height, slope_deg, x, y) {
        if unit(hash2(col as i64, row as i64, SEED), 0) < 0.12 { palette::SCREE } else { palette::ROCK }
    } else if forest(height, slope_deg, x, y) {
        palette::FOREST
    } else {
        palette::OPEN
    };
    let line = if col.is_multiple_of(KM_PX) || row.is_multiple_of(KM_PX) {
        Some(palette::GRID)
    } else if wet == 0 && !river && on_path(&corners.get(i, j), height) {
        Some(palette::PATH)
    } else if (1..4).contains(&wet) || mean(|g| g.stream_m).abs() < 6.0 && wet == 0 && !river {
        Some(palette::SHORE)
    } else if wet == 0 && !river && slope_deg < 48.0 && on_contour(corners, i, j) {
        Some(palette::CONTOUR)
    } else {
        None
    };
    scan_noise(line.unwrap_or(base), col, row)
}

/// Steepest slope of a pixel from its corners, degrees.
fn slope(q: &[Ground; 4]) -> f64 {
    let gx = ((q[1].height_m - q[0].height_m) + (q[3].height_m - q[2].height_m)) / (2.0 * PIXEL_M);
    let gy = ((q[0].height_m - q[2].height_m) + (q[1].height_m - q[3].height_m)) / (2.0 * PIXEL_M);
    (gx * gx + gy * gy).sqrt().atan().to_degrees()
}

/// Bare rock: above a wavering rock line, or cliffs.
fn rock(height: f64, slope_deg: f64, along: f64, across: f64) -> bool {
    let line = 2600.0 + 150.0 * crate::noise::at(along, across, 700.0, SEED + 1);
    height > line || slope_deg > 48.0
}

/// Forest: between the valley floor and a ragged tree line near 2,250 m
/// (the central Alps' tree line), off the steepest slopes, with meadows.
fn forest(height: f64, slope_deg: f64, along: f64, across: f64) -> bool {
    let tree_line = 2250.0 + 150.0 * crate::noise::at(along, across, 450.0, SEED + 2);
    let meadow = crate::noise::fbm(along, across, 900.0, 3, SEED + 3) > 0.3;
    (960.0..tree_line).contains(&height) && slope_deg < 45.0 && !meadow
}

/// A contour crosses the pixel (or, for index contours, the 2 × 2 pixels
/// starting at it).
fn on_contour(corners: &Raster<Ground>, i: usize, j: usize) -> bool {
    let crosses = |span: usize, interval: f64| {
        let (mut lo, mut hi) = (f64::MAX, f64::MIN);
        for dj in 0..=span {
            for di in 0..=span {
                let h = corners.get(i + di, j + dj).height_m;
                lo = lo.min(h);
                hi = hi.max(h);
            }
        }
        (lo / interval).floor() != (hi / interval).floor()
    };
    crosses(1, CONTOUR_M) || crosses(2, INDEX_M)
}

/// Paths: a road 70 m north of the river and trails that follow gentle
/// noise isolines through the forest belt, dashed every 40 m or so.
fn on_path(g: &Ground, height: f64) -> bool {
    if (g.river_m - 70.0).abs() < 6.0 {
        return true;
    }
    if !(950.0..2300.0).contains(&height) {
        return false;
    }
    let trail = crate::noise::at(g.along_m, g.across_m, 2500.0, SEED + 4);
    let dash = unit(hash2((g.along_m / 40.0).floor() as i64, (g.across_m / 40.0).floor() as i64, SEED + 5), 0) < 0.8;
    trail.abs() < 0.0035 && dash
}

/// ±3 levels of per-pixel scanner noise.
fn scan_noise(rgb: [u8; 3], col: usize, row: usize) -> [u8; 3] {
    let h = hash2(col as i64, row as i64, SEED + 6);
    let mut out = rgb;
    for (k, v) in out.iter_mut().enumerate() {
        let d = (unit(h, k as u32 + 1) * 7.0).floor() as i32 - 3;
        *v = (i32::from(*v) + d).clamp(0, 255) as u8;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The whole sheet as colour classes (index into `palette_order`).
    fn sheet() -> Vec<Raster<f32>> {
        let map = MapSource::new().unwrap();
        let blocks = crate::source::Blocks::new(Arc::new(map), &crate::source::BlockCache::new(1 << 30));
        blocks.read(crate::raster::Window::new(0, 0, COLS, ROWS)).unwrap()
    }

    fn nearest_colour(rgb: [f32; 3]) -> usize {
        let all = all_colours();
        let d = |c: [u8; 3]| (0..3).map(|k| (rgb[k] - f32::from(c[k])).abs()).fold(0.0, f32::max);
        (0..all.len()).min_by(|&a, &b| d(all[a]).total_cmp(&d(all[b]))).unwrap()
    }

    fn all_colours() -> [[u8; 3]; 9] {
        use palette::*;
        [FOREST, OPEN, WATER, SHORE, CONTOUR, PATH, ROCK, SCREE, GRID]
    }

    #[test]
    fn the_sheet_reads_like_a_topographic_map() {
        let px = sheet();
        let classes: Vec<usize> =
            (0..COLS * ROWS).map(|i| nearest_colour([0, 1, 2].map(|b| px[b].data()[i]))).collect();
        let share = |k: usize| classes.iter().filter(|&&c| c == k).count() as f64 / classes.len() as f64;
        // Every colour is within the ±3 scanner noise of its palette entry.
        for (i, &c) in classes.iter().enumerate() {
            let want = all_colours()[c];
            assert!((0..3).all(|b| (px[b].data()[i] - f32::from(want[b])).abs() <= 3.0));
        }
        let (forest, water, rock, contour, path) =
            (share(0), share(2) + share(3), share(6) + share(7), share(4), share(5));
        println!("forest {forest:.3} water {water:.3} rock {rock:.3} contours {contour:.3} paths {path:.4}");
        // Green pixels only: contours and paths crossing the forest are counted apart.
        assert!((0.15..0.50).contains(&forest), "forest {forest}");
        assert!((0.01..0.10).contains(&water) && rock > 0.05 && contour > 0.10 && path > 0.001);
    }

    #[test]
    fn the_close_bridges_the_lines_that_cross_forest() {
        use crate::raster::morphology::{MorphOp, apply_sequence};
        let px = sheet();
        let forest = Raster::from_fn(COLS, ROWS, |x, y| {
            if nearest_colour([0, 1, 2].map(|b| px[b].get(x, y))) == 0 { 1.0 } else { 0.0 }
        });
        let closed = apply_sequence(&forest, &MorphOp::parse_sequence("DDEE").unwrap(), 1);
        // Line pixels (contours, paths) with forest on both sides, two pixels away.
        let (mut lines, mut bridged) = (0, 0);
        for y in 2..ROWS - 2 {
            for x in 2..COLS - 2 {
                let class = nearest_colour([0, 1, 2].map(|b| px[b].get(x, y)));
                let across = (forest.get(x - 2, y) == 1.0 && forest.get(x + 2, y) == 1.0)
                    || (forest.get(x, y - 2) == 1.0 && forest.get(x, y + 2) == 1.0);
                if (class == 4 || class == 5) && across {
                    lines += 1;
                    bridged += usize::from(closed.get(x, y) == 1.0);
                }
            }
        }
        let area = closed.data().iter().filter(|&&v| v == 1.0).count() as f64 / (COLS * ROWS) as f64;
        println!("{bridged} of {lines} line pixels inside forest bridged; forest after the close {area:.3}");
        assert!(lines > 10_000 && bridged as f64 / lines as f64 > 0.95, "{bridged}/{lines}");
        assert!((0.25..0.50).contains(&area), "{area}");
    }

    #[test]
    fn blocks_are_deterministic_and_independent() {
        let map = MapSource::new().unwrap();
        let a = map.read_block(3, 2).unwrap();
        assert_eq!(a, map.read_block(3, 2).unwrap());
        // The block's first row equals the same row read as part of the block above's window.
        let blocks =
            crate::source::Blocks::new(Arc::new(MapSource::new().unwrap()), &crate::source::BlockCache::new(1 << 26));
        let window = blocks.read(crate::raster::Window::new(3 * 256 - 7, 2 * 256 - 5, 20, 10)).unwrap();
        for b in 0..3 {
            assert_eq!(window[b].get(7, 5), a[b].get(0, 0));
            assert_eq!(window[b].get(19, 9), a[b].get(12, 4));
        }
    }

    #[test]
    fn the_sheet_covers_the_dem() {
        let g = MapSource::new().unwrap().georef();
        let utm = Crs::from_epsg(32632).unwrap();
        for (lon, lat) in [(9.995, 46.295), (10.255, 46.295), (9.995, 46.455), (10.255, 46.455)] {
            let (e, n) = utm.from_lon_lat(lon, lat).unwrap();
            let (px, py) = ((e - g.x0) / g.dx, (n - g.y0) / g.dy);
            assert!(px > 0.0 && py > 0.0 && px < COLS as f64 - 1.0 && py < ROWS as f64 - 1.0, "{lon} {lat}: {px} {py}");
        }
    }
}
