//! How the demo map draws one pixel: the cartographic rules of the sheet.
//!
//! Area colours, bottom to top: open land; forest (from the valley floor at
//! about 980 m to a ragged tree line near 2,000 m, off slopes steeper than
//! 40°, with meadow clearings); rock above a wavering rock line near 2,450 m
//! or on slopes over 45° (white; scree dotted grey; cliffs, the rock steeper
//! than 45°, hatched grey down the fall line instead of contoured); water
//! (lake and river). Lines over them: the lake shore and
//! river banks (dark blue, 1 px), side streams (dark blue, 1 px), contours
//! every 20 m (brown, 1 px; index contours every 100 m, 2 px) except on water
//! and cliffs, paths (black: the valley road 2 px, dashed trails 1 px), the
//! kilometre grid (1 px).
//!
//! Lines are drawn where a field's level is crossed between a pixel's corners,
//! the digital equivalent of a pen line: one pixel wide whatever the slope
//! (two for index contours and the road, which test a 2 × 2 pixel
//! footprint). So no line crossing the forest is wider than 2 px, and the
//! dissertation's close (two 3 × 3 dilations, two erosions; section 6.3,
//! Figure 6.3) bridges every one of them.
//!
//! Colours carry ±3 levels of per-pixel "scanner" noise, so a colour key needs
//! its tolerance, as with a real scan.

use super::palette;
use super::terrain::{self, Ground};
use crate::noise::{self, hash2, unit};
use crate::raster::floor_i64;

/// Contour interval and index-contour interval, metres (Swiss 1:50,000).
const CONTOUR_M: f64 = 20.0;
const INDEX_M: f64 = 100.0;
/// Pixel size, metres.
const PIXEL_M: f64 = 10.0;
/// tan² of the slope limits: forest stops at 40° (steeper ground is rock or
/// scree in the Alps); rock starts at 45°, where 20 m contours come closer
/// than 2 px and would merge, so steep rock is drawn as a cliff (hatched, no
/// contours) as on Swiss sheets; scree lies below 38°.
const FOREST_MAX_TAN2: f64 = 0.704; // tan² 40°
const ROCK_MIN_TAN2: f64 = 1.0; // tan² 45°
const CLIFF_MIN_TAN2: f64 = ROCK_MIN_TAN2;
const SCREE_MAX_TAN2: f64 = 0.610; // tan² 38°
/// Lowest forest, metres: the valley floor below is farmland.
const FOREST_FLOOR_M: f64 = 980.0;
/// Valley road: 300 m north of the valley's centre line, on the north
/// shore of the lake at 930 m.
const ROAD_ACROSS_M: f64 = 300.0;
const ROAD_SHORE_M: f64 = 930.0;
/// Trails stay below this height, metres.
const TRAIL_TOP_M: f64 = 2400.0;
const SEED: u64 = 0x70B0_5EE7;

/// The slowly varying fields the symbols need (from noise; the map samples
/// them every 80 m and interpolates).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cover {
    /// Tree line, metres.
    pub tree_line_m: f64,
    /// Rock line, metres.
    pub rock_line_m: f64,
    /// Meadow where > 0.
    pub meadow: f64,
    /// Trail where this crosses 0.
    pub trail: f64,
}

impl Cover {
    /// `self + t · (other − self)`, field by field.
    pub fn lerp(&self, other: &Cover, t: f64) -> Cover {
        let l = |a: f64, b: f64| a + t * (b - a);
        Cover {
            tree_line_m: l(self.tree_line_m, other.tree_line_m),
            rock_line_m: l(self.rock_line_m, other.rock_line_m),
            meadow: l(self.meadow, other.meadow),
            trail: l(self.trail, other.trail),
        }
    }
}

/// The cover fields at local position `(x, y)`.
pub fn cover(x: f64, y: f64) -> Cover {
    Cover {
        // Central-Alps tree line with a ragged edge (±60 m over 400 m).
        tree_line_m: 1980.0 + 110.0 * noise::at(x, y, 2500.0, SEED) + 60.0 * noise::at(x, y, 400.0, SEED + 1),
        rock_line_m: 2450.0 + 150.0 * noise::at(x, y, 3000.0, SEED + 2),
        // Clearings a few hundred metres across, ragged down to 280 m,
        // covering about a fifth of the belt.
        meadow: noise::fbm(x, y, 1100.0, 3, SEED + 3) - 0.28,
        // Isolines of a 2.2 km noise: a trail about every kilometre.
        trail: noise::at(x, y, 2200.0, SEED + 4),
    }
}

/// Per-corner bits: the sign of each line field, so that "a line crosses
/// the pixel" is "a bit differs between its corners".
const WET: u8 = 1; // under the lake
const ROAD: u8 = 2; // road field ≥ 0
const TRAIL: u8 = 4; // trail field ≥ 0
const STREAM: u8 = 8; // stream field ≥ 0
const NEAR_STREAM: u8 = 16; // within 30 m of a stream's centre line
const DRY_BANK: u8 = 32; // outside the river's water
const NORTH: u8 = 64; // north of the valley's centre line (where the road runs)

/// The values the symbols need at every pixel corner of a block, row-major.
pub struct Corners {
    cols: usize,
    height_m: Vec<f64>,
    river_m: Vec<f64>,
    contour: Vec<i32>,
    index: Vec<i32>,
    bits: Vec<u8>,
    cover: Vec<Cover>,
}

impl Corners {
    /// Room for `cols × rows` corners, filled row by row with [`Corners::push`].
    pub fn with_capacity(cols: usize, rows: usize) -> Corners {
        let n = cols * rows;
        Corners {
            cols,
            height_m: Vec::with_capacity(n),
            river_m: Vec::with_capacity(n),
            contour: Vec::with_capacity(n),
            index: Vec::with_capacity(n),
            bits: Vec::with_capacity(n),
            cover: Vec::with_capacity(n),
        }
    }

    /// Appends the next corner.
    pub fn push(&mut self, g: &Ground, cover: Cover) {
        let bit = |on: bool, b: u8| if on { b } else { 0 };
        self.height_m.push(g.height_m);
        self.river_m.push(g.river_m);
        self.contour.push(floor_i64(g.height_m * (1.0 / CONTOUR_M)) as i32);
        self.index.push(floor_i64(g.height_m * (1.0 / INDEX_M)) as i32);
        let north = g.across_m > 0.0;
        self.bits.push(
            bit(g.lake_m > 0.0, WET)
                | bit(north && road(g) >= 0.0, ROAD)
                | bit(cover.trail >= 0.0, TRAIL)
                | bit(g.stream_m >= 0.0, STREAM)
                | bit(g.stream_m.abs() < 30.0, NEAR_STREAM)
                | bit(g.river_m.abs() >= terrain::RIVER_HALF_WIDTH_M, DRY_BANK)
                | bit(north, NORTH),
        );
        self.cover.push(cover);
    }

    /// `(or, and)` of the bits of the `n × n` corners from `(i, j)`.
    #[inline]
    fn bits(&self, i: usize, j: usize, n: usize) -> (u8, u8) {
        let (mut or, mut and) = (0, u8::MAX);
        for r in j..j + n {
            for &b in &self.bits[r * self.cols + i..][..n] {
                or |= b;
                and &= b;
            }
        }
        (or, and)
    }

    /// Whether the level index changes over the `n × n` corners from `(i, j)`.
    #[inline]
    fn level_changes(levels: &[i32], cols: usize, i: usize, j: usize, n: usize) -> bool {
        let k = j * cols + i;
        let first = levels[k];
        let (mut lo, mut hi) = (first, first);
        for r in 0..n {
            for &l in &levels[k + r * cols..][..n] {
                lo = lo.min(l);
                hi = hi.max(l);
            }
        }
        lo != hi
    }
}

/// The road field: the valley road 300 m north of the valley's centre line,
/// blending over 600 m at both ends of the lake into the north-shore road
/// at 930 m. Metres of height weigh three times metres across, as the shore
/// rises about a third of a metre per metre.
fn road(g: &Ground) -> f64 {
    let valley = g.across_m - ROAD_ACROSS_M;
    if !(-6700.0..1300.0).contains(&g.along_m) {
        return valley;
    }
    let shore = 3.0 * (g.height_m - ROAD_SHORE_M);
    let blend = smooth01((g.along_m + 6700.0) / 600.0) * smooth01((1300.0 - g.along_m) / 600.0);
    valley + blend * (shore - valley)
}

/// The colour of the pixel at `(col, row)` of the sheet whose north-west
/// corner is `(i, j)` in `corners` (which has at least one corner of margin
/// before and two after it).
pub fn draw(corners: &Corners, i: usize, j: usize, col: usize, row: usize) -> [u8; 3] {
    let cols = corners.cols;
    let k = j * cols + i;
    let h = &corners.height_m;
    let height = 0.25 * (h[k] + h[k + 1] + h[k + cols] + h[k + cols + 1]);
    let r = &corners.river_m;
    let in_river = (0.25 * (r[k] + r[k + 1] + r[k + cols] + r[k + cols + 1])).abs() < terrain::RIVER_HALF_WIDTH_M;
    let (or, and) = corners.bits(i, j, 2);
    let crossed = or ^ and;
    let cover = &corners.cover[k];
    let (gx, gy) = gradient(h, cols, k);
    let tan2 = gx * gx + gy * gy;
    let base = if and & WET != 0 || in_river {
        palette::WATER
    } else if height > cover.rock_line_m && tan2 > 0.2 || tan2 > ROCK_MIN_TAN2 {
        rock(tan2, gx, gy, col, row)
    } else if (FOREST_FLOOR_M..cover.tree_line_m).contains(&height) && tan2 < FOREST_MAX_TAN2 && cover.meadow < 0.0 {
        palette::FOREST
    } else {
        palette::OPEN
    };
    let dry = or & WET == 0 && !in_river;
    let line = if col.is_multiple_of(KM_PX) || row.is_multiple_of(KM_PX) {
        Some(palette::GRID)
    } else if or & WET == 0 && on_path(corners, i, j, crossed, height, col, row) {
        Some(palette::PATH)
    } else if crossed & WET != 0
        || or & WET == 0 && crossed & DRY_BANK != 0
        || dry && crossed & STREAM != 0 && and & NEAR_STREAM != 0
    {
        Some(palette::SHORE)
    } else if dry
        && tan2 < CLIFF_MIN_TAN2
        && (Corners::level_changes(&corners.contour, cols, i, j, 2)
            || Corners::level_changes(&corners.index, cols, i, j, 3))
    {
        Some(palette::CONTOUR)
    } else {
        None
    };
    scan_noise(line.unwrap_or(base), col, row)
}

/// Pixels per kilometre: pixels whose west or north edge is on a grid line
/// draw it (the sheet's corner is on the grid).
pub const KM_PX: usize = 100;

/// Slope `(∂h/∂x, ∂h/∂y)` (x east, y south) over the 3 × 3 pixels around
/// the pixel whose north-west corner is `k`: smoother than one pixel's
/// corners, so rock and forest edges do not fray on the gullies.
fn gradient(h: &[f64], cols: usize, k: usize) -> (f64, f64) {
    let (up, down) = (k - cols, k + 2 * cols);
    let gx = (h[k + 2] + h[k + cols + 2] - h[k - 1] - h[k + cols - 1]) / (2.0 * 3.0 * PIXEL_M);
    let gy = (h[down] + h[down + 1] - h[up] - h[up + 1]) / (2.0 * 3.0 * PIXEL_M);
    (gx, gy)
}

/// Rock: cliffs hatched down the fall line (a line every 4 px, in the
/// nearest of four directions, as a cartographer's pen would), scree dotted
/// (one dot in about half of the 3 × 3 px cells), bare rock white.
fn rock(tan2: f64, gx: f64, gy: f64, col: usize, row: usize) -> [u8; 3] {
    if tan2 >= CLIFF_MIN_TAN2 {
        // Fall line within 22.5° of the axes (tan 22.5° ≈ 0.414) or diagonal.
        let (ax, ay) = (gx.abs(), gy.abs());
        let phase = if ay < 0.414 * ax {
            row
        } else if ax < 0.414 * ay {
            col
        } else if (gx > 0.0) == (gy > 0.0) {
            col + 3 * row // lines running ↘ (−1 ≡ 3 mod 4)
        } else {
            col + row
        };
        return if phase % 4 == 0 { palette::SCREE } else { palette::ROCK };
    }
    if tan2 < SCREE_MAX_TAN2 {
        let (cx, cy) = (col / 3, row / 3);
        let h = hash2(cx as i64, cy as i64, SEED + 5);
        let dot = (cx * 3 + (h % 3) as usize, cy * 3 + ((h >> 2) % 3) as usize);
        if unit(h, 1) < 0.5 && dot == (col, row) {
            return palette::SCREE;
        }
    }
    palette::ROCK
}

/// The valley road (a 2 × 2 pixel footprint, north of the valley's centre
/// line) and the dashed trails (1 px) between the valley floor and the
/// trail top. `crossed` has the bits that differ between the pixel's corners.
fn on_path(corners: &Corners, i: usize, j: usize, crossed: u8, height: f64, col: usize, row: usize) -> bool {
    let (or3, and3) = corners.bits(i, j, 3);
    if and3 & NORTH != 0 && (or3 ^ and3) & ROAD != 0 {
        return true;
    }
    // Dashes: 4 of 5 cells of 3 × 3 px keep the trail.
    crossed & TRAIL != 0
        && (FOREST_FLOOR_M..TRAIL_TOP_M).contains(&height)
        && unit(hash2((col / 3) as i64, (row / 3) as i64, SEED + 6), 0) < 0.8
}

/// ±3 levels of per-pixel scanner noise.
fn scan_noise(rgb: [u8; 3], col: usize, row: usize) -> [u8; 3] {
    let h = hash2(col as i64, row as i64, SEED + 7);
    let mut out = rgb;
    for (k, v) in out.iter_mut().enumerate() {
        let d = (unit(h, k as u32 + 1) * 7.0) as i32 - 3;
        *v = (i32::from(*v) + d).clamp(0, 255) as u8;
    }
    out
}

/// Smoothstep of `t` clamped to `[0, 1]`.
fn smooth01(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Draws a 60 × 60 pixel forested plane whose fall line points
    /// `angle_deg` from east, rising `rise_m` per pixel.
    fn plane(angle_deg: f64, rise_m: f64) -> Vec<[u8; 3]> {
        let (c, s) = (angle_deg.to_radians().cos(), angle_deg.to_radians().sin());
        let n = 63;
        let mut corners = Corners::with_capacity(n, n);
        for j in 0..n {
            for i in 0..n {
                let g = Ground {
                    height_m: 1503.0 + rise_m * (i as f64 * c + j as f64 * s),
                    lake_m: -50.0,
                    river_m: 1000.0,
                    stream_m: 1.0e6,
                    along_m: 0.0,
                    across_m: -5000.0,
                };
                corners.push(&g, Cover { tree_line_m: 3000.0, rock_line_m: 5000.0, meadow: -1.0, trail: 1.0 });
            }
        }
        (0..60 * 60).map(|k| draw(&corners, k % 60 + 1, k / 60 + 1, k % 60 + 1, k / 60 + 1)).collect()
    }

    #[test]
    fn the_close_bridges_contours_at_any_angle_up_to_the_forest_limit() {
        use crate::raster::Raster;
        use crate::raster::morphology::{MorphOp, apply_sequence};
        let near = |p: [u8; 3], c: [u8; 3]| (0..3).all(|b| (i32::from(p[b]) - i32::from(c[b])).abs() <= 3);
        // 2 m a pixel: contours 10 px apart; 6.5 m a pixel (33°): 3 px apart.
        for rise_m in [2.0, 6.5] {
            for angle in [0.0, 10.0, 30.0, 45.0, 60.0, 80.0, 135.0] {
                let px = plane(angle, rise_m);
                let lines = px.iter().filter(|&&p| near(p, palette::CONTOUR)).count();
                let forest = px.iter().filter(|&&p| near(p, palette::FOREST)).count();
                assert_eq!(lines + forest, px.len(), "{angle}° {rise_m} m: only forest and contours");
                assert!(lines > px.len() / 12, "{angle}° {rise_m} m: {lines} contour pixels");
                let mask = Raster::from_vec(
                    60,
                    60,
                    px.iter().map(|&p| f32::from(u8::from(near(p, palette::FOREST)))).collect(),
                )
                .unwrap();
                let closed = apply_sequence(&mask, &MorphOp::parse_sequence("DDEE").unwrap(), 1);
                // Away from the edges (where the close sees only the buffer) all is forest.
                let holes =
                    (4..56).flat_map(|y| (4..56).map(move |x| (x, y))).filter(|&(x, y)| closed.get(x, y) < 1.0).count();
                assert_eq!(holes, 0, "{angle}° {rise_m} m: the close leaves {holes} line pixels");
            }
        }
    }

    #[test]
    fn scanner_noise_stays_within_three_levels() {
        for k in 0..1000 {
            let c = scan_noise(palette::FOREST, k, 7 * k);
            assert!((0..3).all(|b| (i32::from(c[b]) - i32::from(palette::FOREST[b])).abs() <= 3));
        }
    }
}
