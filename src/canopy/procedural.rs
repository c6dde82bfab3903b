//! The built-in procedural canopy proxy: one tree per world cell, placed,
//! sized and sometimes left out by a hash of the cell, so the canopy is
//! anchored to the globe and never repeats.
//!
//! Cells are `cell_m` high; each latitude row of cells has a whole number of
//! columns around the globe (`⌊2πR cos φ / cell⌋`), so cells stay roughly
//! square at every latitude and wrap exactly at the antimeridian. A tree's
//! crown is `H · (1 − (d/r)^p)` for `d < r`; the canopy is the highest crown
//! over a sample, 0 in gaps, with east–west distances measured at the scale of
//! the tree's cell row (its middle latitude). Crowns are at most one cell wide
//! in radius, so only the 3 × 3 neighbouring cells can reach a sample.
//!
//! Filtering to the sample spacing `s`: below `cell/2` the crowns are sampled
//! as they are (a crown spans at least three samples); from `1.5·cell` on
//! single crowns would alias, and the proxy is its mean height; in between
//! the two are blended (smoothstep). This is the
//! "filtered to the tile's sample spacing" of `../shared/DESIGN.md` stage 3.
//!
//! Each crown value is computed from the sample's normalised coordinates and
//! the tree's canonical position only, so any grid that contains a sample gives
//! it bitwise the same height.

use super::CanopyProxy;
use crate::geo::EARTH_RADIUS_M;
use crate::grid::lattice::Globe;
use crate::grid::{Axis, SampleGrid};
use crate::noise::{hash2, unit};
use crate::raster::Raster;
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// Parameters of the procedural proxy (defaults: a mature conifer stand).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProxyParams {
    /// Mean distance between trees, metres.
    pub cell_m: f64,
    /// Height of the tallest trees, metres.
    pub height_m: f32,
    /// Trees are `height_m · (1 − u · variation)` tall, u uniform in [0, 1).
    pub height_variation: f32,
    /// Crown radius as a fraction of the cell (≤ 1).
    pub crown_radius: f64,
    /// Crown profile exponent `p` (1 = cone, 2 = paraboloid).
    pub crown_exponent: f32,
    /// Share of cells without a tree (gaps).
    pub gap_fraction: f64,
    /// Seed of the hash; change it for an independent forest.
    pub seed: u64,
}

impl ProxyParams {
    /// Each parameter in its range (what [`ProceduralProxy::new`] would
    /// otherwise clamp), or the first that is not, named.
    pub fn check(&self) -> Result<(), String> {
        let ranges = [
            ("cell_m", self.cell_m, 0.5, 1000.0),
            ("height_m", f64::from(self.height_m), 0.0, 150.0),
            ("height_variation", f64::from(self.height_variation), 0.0, 1.0),
            ("crown_radius", self.crown_radius, 0.05, 1.0),
            ("crown_exponent", f64::from(self.crown_exponent), 0.25, 8.0),
            ("gap_fraction", self.gap_fraction, 0.0, 1.0),
        ];
        match ranges.into_iter().find(|&(_, v, lo, hi)| !(lo..=hi).contains(&v)) {
            Some((key, v, lo, hi)) => Err(format!("{key} = {v}: must be {lo} to {hi}")),
            None => Ok(()),
        }
    }
}

impl Default for ProxyParams {
    fn default() -> Self {
        ProxyParams {
            cell_m: 7.0,
            height_m: 25.0,
            height_variation: 0.35,
            crown_radius: 0.8,
            crown_exponent: 1.5,
            gap_fraction: 0.08,
            seed: 0x005E_EDCA_110F_7EE5,
        }
    }
}

/// The procedural proxy.
#[derive(Clone, Debug)]
pub struct ProceduralProxy {
    params: ProxyParams,
    /// Radians of latitude per cell row.
    row_rad: f64,
    radius_m: f64,
    /// `1 / radius_m²`.
    inv_radius2: f64,
    mean_m: f32,
}

/// One tree: canonical longitude and latitude (radians), size, and the
/// east–west metres per radian of longitude of its cell row (at the row's
/// middle).
#[derive(Clone, Copy, Debug)]
struct Tree {
    lon: f64,
    lat: f64,
    height: f32,
    east_m_per_rad: f64,
}

/// A row of cells: its index, its columns around the globe, their width in
/// radians and the east–west scale at the row's middle.
#[derive(Clone, Copy, Debug)]
struct CellRow {
    j: i64,
    columns: i64,
    column_rad: f64,
    east_m_per_rad: f64,
}

impl ProceduralProxy {
    /// A proxy with these parameters (clamped to sensible ranges).
    pub fn new(params: ProxyParams) -> ProceduralProxy {
        let mut p = params;
        p.cell_m = p.cell_m.clamp(0.5, 1000.0);
        p.crown_radius = p.crown_radius.clamp(0.05, 1.0);
        p.gap_fraction = p.gap_fraction.clamp(0.0, 1.0);
        p.height_variation = p.height_variation.clamp(0.0, 1.0);
        p.crown_exponent = p.crown_exponent.clamp(0.25, 8.0);
        let mut proxy = ProceduralProxy {
            row_rad: p.cell_m / EARTH_RADIUS_M,
            radius_m: p.crown_radius * p.cell_m,
            inv_radius2: 1.0 / (p.crown_radius * p.cell_m).powi(2),
            mean_m: 0.0,
            params: p,
        };
        proxy.mean_m = proxy.measure_mean();
        proxy
    }

    /// The parameters in use.
    pub fn params(&self) -> &ProxyParams {
        &self.params
    }

    /// Mean canopy height over a large patch (what coarse levels show).
    pub fn mean_height_m(&self) -> f32 {
        self.mean_m
    }

    /// Weight of the mean in the blend at sample spacing `spacing_m`.
    fn blend(&self, spacing_m: f64) -> f32 {
        let c = self.params.cell_m;
        let t = ((spacing_m - 0.5 * c) / c).clamp(0.0, 1.0);
        (t * t * (3.0 - 2.0 * t)) as f32
    }

    /// Row `j` of cells: `⌊2πR cos φ / cell⌋` columns at its middle latitude φ.
    fn cell_row(&self, j: i64) -> CellRow {
        let lat = ((j as f64 + 0.5) * self.row_rad).clamp(-PI / 2.0, PI / 2.0);
        let east_m_per_rad = EARTH_RADIUS_M * lat.cos();
        let columns = ((TAU * east_m_per_rad / self.params.cell_m).floor() as i64).max(1);
        CellRow { j, columns, column_rad: TAU / columns as f64, east_m_per_rad }
    }

    /// The tree of cell `i` (taken modulo the columns) of `row`, if the cell
    /// is not a gap.
    #[inline]
    fn planted(&self, row: CellRow, i: i64) -> Option<Tree> {
        let i = i.rem_euclid(row.columns);
        let h = hash2(row.j, i, self.params.seed);
        if unit(h, 0) < self.params.gap_fraction {
            return None;
        }
        // Keep centres away from cell edges so crowns of radius ≤ 1 cell reach
        // only neighbouring cells.
        let jitter = |k| 0.15 + 0.7 * unit(h, k);
        let p = &self.params;
        Some(Tree {
            lon: -PI + (i as f64 + jitter(1)) * row.column_rad,
            lat: (row.j as f64 + jitter(2)) * self.row_rad,
            height: p.height_m * (1.0 - unit(h, 3) as f32 * p.height_variation),
            east_m_per_rad: row.east_m_per_rad,
        })
    }

    /// North–south metres from latitude `lat` (radians) to `tree`, if its
    /// crown reaches that latitude.
    #[inline]
    fn reaches(&self, tree: &Tree, lat: f64) -> Option<f64> {
        let dy = (lat - tree.lat) * EARTH_RADIUS_M;
        (dy.abs() < self.radius_m).then_some(dy)
    }

    /// Crown height of `tree` at normalised longitude `lon` (radians), on a
    /// row `dy2` square metres north or south of it; 0 outside the crown.
    /// Branch-free past the antimeridian test: samples in and out of crowns
    /// alternate unpredictably.
    #[inline]
    fn crown(&self, tree: &Tree, lon: f64, dy2: f64) -> f32 {
        let mut dlon = lon - tree.lon;
        if dlon > PI {
            dlon -= TAU;
        } else if dlon < -PI {
            dlon += TAU;
        }
        let dx = dlon * tree.east_m_per_rad;
        let q = ((dx * dx + dy2) * self.inv_radius2) as f32;
        // (d/r)^p ≥ 1 outside the crown, so the height there is ≤ 0.
        (tree.height * (1.0 - self.profile(q))).max(0.0)
    }

    /// `(d/r)^p` from `q = (d/r)²`, without `powf` for the usual exponents.
    #[inline]
    fn profile(&self, q: f32) -> f32 {
        match self.params.crown_exponent {
            1.0 => q.sqrt(),
            1.5 => {
                let d = q.sqrt();
                d * d.sqrt()
            }
            2.0 => q,
            p => q.powf(0.5 * p),
        }
    }

    fn measure_mean(&self) -> f32 {
        // 50 × 50 cells at a quarter-cell spacing, away from any pole.
        let n = 200;
        let step = self.params.cell_m / 4.0 / crate::geo::METRES_PER_DEGREE;
        let grid = SampleGrid { lon: Axis::degrees(7.0, step, 0, n), lat: Axis::degrees(0.5, -step, 0, n) };
        let mut row = vec![0.0f32; n];
        let mut sum = 0.0f64;
        let mut splat = Splat::new(self, &grid);
        for r in 0..n {
            row.fill(0.0);
            splat.row(r, &mut row, &[(0, n)]);
            sum += row.iter().map(|&v| v as f64).sum::<f64>();
        }
        (sum / (n * n) as f64) as f32
    }
}

/// Columns of slack around a crown's chord, for rounding in its end points.
const SLACK: f64 = 1e-6;

/// Rows of samples one [`Splat`] draws in turn (its trees are reused
/// between them: a crown spans several rows).
const BAND_ROWS: usize = 16;

/// Full-detail crowns, drawn row after row over one grid. Trees are planted
/// (hashed) once per cell and kept while rows go by, each row's longitudes
/// are computed once, and a crown is evaluated only at the columns under its
/// chord on the row.
struct Splat<'a> {
    proxy: &'a ProceduralProxy,
    globe: Globe<'a>,
    /// Longitudes (radians) of the columns, and the bits of the first: rows
    /// past a pole read the opposite meridian, where it differs.
    lons: Vec<f64>,
    lon0_bits: Option<u64>,
    /// Ranges of columns over which the longitude increases.
    segments: Vec<(usize, usize)>,
    /// Trees of the cell rows met so far, per segment.
    planted: Vec<Planted>,
}

/// The trees of one cell row over the cells a segment of columns reaches
/// (none kept when cells are much narrower than columns: each tree then
/// meets at most one sample, and the cells of a wide grid would not fit).
struct Planted {
    row: CellRow,
    segment: usize,
    /// Cell index of `trees[0]`.
    i0: i64,
    trees: Vec<Cell>,
}

/// Most cells kept per column of a segment.
const CELLS_PER_COLUMN: usize = 4;

/// A cell, not yet hashed, without a tree, or with one.
#[derive(Clone, Copy)]
enum Cell {
    Unknown,
    Gap,
    Tree(Tree),
}

impl<'a> Splat<'a> {
    fn new(proxy: &'a ProceduralProxy, grid: &'a SampleGrid) -> Splat<'a> {
        Splat {
            proxy,
            globe: grid.globe(),
            lons: Vec::new(),
            lon0_bits: None,
            segments: Vec::new(),
            planted: Vec::new(),
        }
    }

    /// Crowns of grid row `r` into `out` (which holds 0 or lower values),
    /// over the column ranges `runs` (the wanted samples).
    fn row(&mut self, r: usize, out: &mut [f32], runs: &[(usize, usize)]) {
        if runs.is_empty() {
            return;
        }
        let p = self.proxy;
        let lat = self.globe.at(0, r as i64).1.to_radians();
        self.longitudes(r, out.len());
        // Rows of cells whose trees (centres 0.15–0.85 into the cell) can
        // reach this latitude: about 2.3 of the 3 around it.
        let reach = p.radius_m / EARTH_RADIUS_M;
        let j_lo = ((lat - reach) / p.row_rad - 0.85).floor() as i64;
        let j_hi = ((lat + reach) / p.row_rad - 0.15).floor() as i64;
        let radius2 = p.radius_m * p.radius_m;
        for s in 0..self.segments.len() {
            let (start, end) = self.segments[s];
            let (la, lb) = (self.lons[start], self.lons[end - 1]);
            let per_step = if end - start > 1 && lb > la { (end - start - 1) as f64 / (lb - la) } else { 1.0 };
            let column = |lon: f64| start as f64 + (lon - la) * per_step;
            for &(a, b) in runs {
                let (a, b) = (a.max(start), b.min(end));
                if a >= b {
                    continue;
                }
                for j in j_lo..=j_hi {
                    let k = self.cell_row(j, s);
                    let row = self.planted[k].row;
                    let col = |lon: f64| ((lon + PI) / row.column_rad).floor() as i64;
                    for i in col(self.lons[a]) - 1..=col(self.lons[b - 1]) + 1 {
                        let Some(tree) = self.tree(k, i) else { continue };
                        let Some(dy) = p.reaches(&tree, lat) else { continue };
                        let dy2 = dy * dy;
                        // The crown's chord on this row, in columns: every
                        // sample inside the crown lies on it.
                        let half = (radius2 - dy2).max(0.0).sqrt() / tree.east_m_per_rad;
                        let mut centre = tree.lon;
                        // The tree may sit on the other side of the antimeridian from the row.
                        if centre - la > PI {
                            centre -= TAU;
                        } else if la - centre > PI {
                            centre += TAU;
                        }
                        let first = ((column(centre - half) - SLACK).ceil() as i64).max(a as i64);
                        let last = ((column(centre + half) + SLACK).floor() as i64).min(b as i64 - 1);
                        for c in first..=last {
                            let c = c as usize;
                            out[c] = out[c].max(p.crown(&tree, self.lons[c], dy2));
                        }
                    }
                }
            }
        }
    }

    /// Longitudes and monotone segments of row `r`'s `width` columns.
    fn longitudes(&mut self, r: usize, width: usize) {
        let first = self.globe.at(0, r as i64).0.to_bits();
        if self.lon0_bits == Some(first) && self.lons.len() == width {
            return;
        }
        self.lons = (0..width).map(|c| self.globe.at(c as i64, r as i64).0.to_radians()).collect();
        self.lon0_bits = Some(first);
        let lons = &self.lons;
        self.segments = monotone_segments(0, width, &|c| lons[c]);
        // Cells were indexed along the old segments.
        self.planted.clear();
    }

    /// Index in `planted` of cell row `j` over segment `s`.
    fn cell_row(&mut self, j: i64, s: usize) -> usize {
        if let Some(k) = self.planted.iter().position(|t| t.row.j == j && t.segment == s) {
            return k;
        }
        let row = self.proxy.cell_row(j);
        let (start, end) = self.segments[s];
        let col = |lon: f64| ((lon + PI) / row.column_rad).floor() as i64;
        let i0 = col(self.lons[start]) - 1;
        let cells = (col(self.lons[end - 1]) + 2 - i0).max(0) as usize;
        let cells = if cells <= CELLS_PER_COLUMN * (end - start) + 8 { cells } else { 0 };
        self.planted.push(Planted { row, segment: s, i0, trees: vec![Cell::Unknown; cells] });
        self.planted.len() - 1
    }

    /// The tree of cell `i` of `planted[k]`, planted on first use.
    #[inline]
    fn tree(&mut self, k: usize, i: i64) -> Option<Tree> {
        let set = &mut self.planted[k];
        if set.trees.is_empty() {
            return self.proxy.planted(set.row, i);
        }
        let cell = &mut set.trees[(i - set.i0) as usize];
        if let Cell::Unknown = cell {
            *cell = self.proxy.planted(set.row, i).map_or(Cell::Gap, Cell::Tree);
        }
        match *cell {
            Cell::Tree(t) => Some(t),
            _ => None,
        }
    }
}

/// Index ranges within `start..end` over which `lon_of` increases (a row
/// crossing the antimeridian has two).
fn monotone_segments(start: usize, end: usize, lon_of: &impl Fn(usize) -> f64) -> Vec<(usize, usize)> {
    let mut segments = Vec::new();
    let mut from = start;
    for c in start + 1..end {
        if lon_of(c) < lon_of(c - 1) {
            segments.push((from, c));
            from = c;
        }
    }
    if end > start {
        segments.push((from, end));
    }
    segments
}

impl CanopyProxy for ProceduralProxy {
    fn heights(&self, grid: &SampleGrid, cover: Option<&Raster<f32>>) -> Raster<f32> {
        use rayon::prelude::*;
        let mut out = Raster::filled(grid.width(), grid.height(), 0.0f32);
        let blend = self.blend(grid.lat.step_deg() * crate::geo::METRES_PER_DEGREE);
        let width = grid.width().max(1);
        out.data_mut().par_chunks_mut(width * BAND_ROWS).enumerate().for_each(|(band, rows)| {
            let mut splat = Splat::new(self, grid);
            for (k, row) in rows.chunks_mut(width).enumerate() {
                let r = band * BAND_ROWS + k;
                let spans = super::covered_runs(cover, r, row.len());
                if blend < 1.0 {
                    splat.row(r, row, &spans);
                }
                if blend > 0.0 {
                    for &(start, end) in &spans {
                        for v in &mut row[start..end] {
                            *v += blend * (self.mean_m - *v);
                        }
                    }
                }
            }
        });
        out
    }

    fn alike_at(&self, spacing_a_m: f64, spacing_b_m: f64) -> bool {
        // Crowns alone (blend 0) or the mean alone (blend 1) on both.
        self.blend(spacing_a_m) == self.blend(spacing_b_m)
    }

    fn max_height_m(&self) -> f32 {
        self.params.height_m
    }

    fn describe(&self) -> String {
        let p = &self.params;
        format!(
            "procedural: one tree per {:.1} m cell, crowns r = {:.1} m, heights {:.1}–{:.1} m, {:.0} % gaps, mean {:.1} m",
            p.cell_m,
            self.radius_m,
            p.height_m * (1.0 - p.height_variation),
            p.height_m,
            100.0 * p.gap_fraction,
            self.mean_m
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{BBox, TileGrid, TileId};

    fn proxy() -> ProceduralProxy {
        ProceduralProxy::new(ProxyParams::default())
    }

    /// Brute force: the highest crown over all trees in the 3×3 cells around.
    fn brute(p: &ProceduralProxy, (lon, lat): (f64, f64)) -> f32 {
        let (lon, lat) = (lon.to_radians(), lat.to_radians());
        let j0 = (lat / p.row_rad).floor() as i64;
        let mut best = 0.0f32;
        for j in j0 - 1..=j0 + 1 {
            let row = p.cell_row(j);
            let i0 = ((lon + PI) / row.column_rad).floor() as i64;
            for i in i0 - 1..=i0 + 1 {
                if let Some((t, dy)) = p.planted(row, i).and_then(|t| Some((t, p.reaches(&t, lat)?))) {
                    best = best.max(p.crown(&t, lon, dy * dy));
                }
            }
        }
        best
    }

    #[test]
    fn splatting_equals_the_per_sample_definition_bitwise() {
        let p = proxy();
        let tiles = TileGrid::new(36.0, 65).unwrap();
        for tile in
            [TileId::new(16, 200_000, 300_000), TileId::new(15, 0, 0), TileId::new(16, 5 * 65536 - 1, 10 * 65536 - 1)]
        {
            let grid = tiles.tile_samples(tile, 3);
            let h = p.heights(&grid, None);
            for y in 0..grid.height() {
                for x in 0..grid.width() {
                    assert_eq!(
                        h.get(x, y).to_bits(),
                        brute(&p, grid.on_globe(x as i64, y as i64)).to_bits(),
                        "{tile} {x} {y}"
                    );
                }
            }
        }
    }

    #[test]
    fn forest_has_trees_and_gaps_within_its_height_range() {
        let p = proxy();
        let grid = BBox::parse("10,46,10.002,46.002")
            .unwrap()
            .point_grid(200, 200, &TileGrid::new(36.0, 513).unwrap())
            .unwrap();
        let h = p.heights(&grid, None);
        let (lo, hi) = h.min_max().unwrap();
        assert_eq!(lo, 0.0);
        assert!(hi > 0.8 * p.params.height_m && hi <= p.params.height_m);
        assert!(p.mean_height_m() > 5.0 && p.mean_height_m() < p.params.height_m);
    }

    #[test]
    fn coarse_grids_see_the_mean_and_unwanted_samples_stay_zero() {
        let p = proxy();
        let grid =
            BBox::parse("10,46,10.1,46.1").unwrap().point_grid(20, 20, &TileGrid::new(36.0, 513).unwrap()).unwrap();
        let left = Raster::from_fn(20, 20, |x, _| if x < 10 { 1.0 } else { 0.0 });
        let h = p.heights(&grid, Some(&left));
        assert!(h.data().iter().enumerate().all(|(i, &v)| if i % 20 < 10 { v == p.mean_height_m() } else { v == 0.0 }));
    }
}
