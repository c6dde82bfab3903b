//! World Wind tile math and request grids (pure: no I/O).
//!
//! Conventions (NASA World Wind `LevelSet`/`Tile`): geographic EPSG:4326, tile
//! origin (−90°, −180°), row 0 at the south, column 0 at −180°, level `n` has
//! tile delta `D0 / 2ⁿ`. Samples are point-registered: an `N × N` tile spans its
//! sector edges inclusive with spacing `delta / (N − 1)`, so neighbours share
//! their edge samples. A halo of `B` samples per side extends a tile onto its
//! neighbours' lattice (dissertation Figure 6.5, bottom).
//!
//! Invariant: every tile and lattice-aligned request on level `n` takes its
//! sample coordinates from the same global lattice (see [`lattice`]).

pub mod lattice;
pub mod mercator;
pub mod quad;

pub use lattice::{Axis, SampleGrid};

use thiserror::Error;

/// What was wrong with a grid parameter or request.
#[derive(Debug, Error, PartialEq)]
pub enum GridError {
    /// The level-0 tile delta does not divide 180°.
    #[error("level-0 tile delta {0}° must divide 180° (e.g. 36, 20, 10)")]
    BadDelta(f64),
    /// Tiles need at least two samples per side.
    #[error("tiles need 2 to {MAX_TILE_SAMPLES} samples per side, got {0}")]
    BadSamples(u32),
    /// Level beyond what the indices can hold.
    #[error("level {level} is beyond the deepest level {max}")]
    LevelTooDeep {
        /// Requested level.
        level: u32,
        /// Deepest level this grid supports.
        max: u32,
    },
    /// Row or column past the end of the level.
    #[error("tile {level}/{row}/{col} does not exist (level {level} has {rows} rows × {cols} columns)")]
    NoSuchTile {
        /// Level.
        level: u32,
        /// Row.
        row: u64,
        /// Column.
        col: u64,
        /// Rows on that level.
        rows: u64,
        /// Columns on that level.
        cols: u64,
    },
    /// A bounding box that is empty, inverted, or off the globe.
    #[error("invalid bounding box: {0}")]
    BadBBox(String),
    /// A request size of zero or beyond the limit.
    #[error("invalid size {width}×{height}: {reason}")]
    BadSize {
        /// Requested width.
        width: usize,
        /// Requested height.
        height: usize,
        /// Why it was refused.
        reason: String,
    },
}

/// A tile address: level, row (from the south) and column (from −180°). (The
/// seed walks the XYZ and WMTS sets with rows from the north: see
/// `seed::pyramid`.)
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileId {
    /// Quadtree level, 0 = coarsest.
    pub level: u32,
    /// Row counted from the south pole.
    pub row: u64,
    /// Column counted from −180°.
    pub col: u64,
}

impl TileId {
    /// A tile address (not checked against a grid; see [`TileGrid::check`]).
    pub fn new(level: u32, row: u64, col: u64) -> Self {
        TileId { level, row, col }
    }

    /// The tile one level up that contains this one.
    pub fn parent(&self) -> Option<TileId> {
        (self.level > 0).then(|| TileId::new(self.level - 1, self.row / 2, self.col / 2))
    }

    /// The four tiles one level down, row-major from the first row: south-west
    /// first where rows count from the south (World Wind, Cesium), north-west
    /// first where they count from the north (the XYZ and WMTS sets).
    pub fn children(&self) -> [TileId; 4] {
        let (l, r, c) = (self.level + 1, self.row * 2, self.col * 2);
        [TileId::new(l, r, c), TileId::new(l, r, c + 1), TileId::new(l, r + 1, c), TileId::new(l, r + 1, c + 1)]
    }
}

impl std::fmt::Display for TileId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}/{}", self.level, self.row, self.col)
    }
}

/// A lat/lon rectangle, degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sector {
    /// Southern edge.
    pub min_lat: f64,
    /// Northern edge.
    pub max_lat: f64,
    /// Western edge.
    pub min_lon: f64,
    /// Eastern edge.
    pub max_lon: f64,
}

impl Sector {
    /// The same sector as a box.
    pub fn bbox(&self) -> BBox {
        BBox { west: self.min_lon, south: self.min_lat, east: self.max_lon, north: self.max_lat }
    }

    /// True if the two sectors overlap in more than an edge.
    pub fn intersects(&self, other: &Sector) -> bool {
        self.min_lat < other.max_lat
            && other.min_lat < self.max_lat
            && self.min_lon < other.max_lon
            && other.min_lon < self.max_lon
    }

    /// True if the two sectors overlap in more than an edge, longitudes
    /// taken modulo 360° (either may reach past ±180°).
    pub fn meets_on_globe(&self, other: &Sector) -> bool {
        self.turns().iter().any(|s| s.intersects(other))
    }

    /// The sector as it is and turned a world east and west: where a sector
    /// reaching past ±180° meets sectors within it.
    pub fn turns(&self) -> [Sector; 3] {
        [0.0, 360.0, -360.0].map(|turn| Sector { min_lon: self.min_lon + turn, max_lon: self.max_lon + turn, ..*self })
    }

    /// True if the point lies in the sector, edges included.
    pub fn contains(&self, lon: f64, lat: f64) -> bool {
        (self.min_lat..=self.max_lat).contains(&lat) && (self.min_lon..=self.max_lon).contains(&lon)
    }

    /// The sector widened by `d_lat` and `d_lon` degrees on each side.
    pub fn grown(&self, d_lat: f64, d_lon: f64) -> Sector {
        Sector {
            min_lat: self.min_lat - d_lat,
            max_lat: self.max_lat + d_lat,
            min_lon: self.min_lon - d_lon,
            max_lon: self.max_lon + d_lon,
        }
    }
}

/// The tiling: level-0 delta `D0` and samples per side `N`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileGrid {
    level0_delta_deg: f64,
    samples: u32,
}

impl TileGrid {
    /// Deepest level supported: row and column indices and global sample
    /// indices must stay exact in `f64` (2⁵³) with any `D0` ≥ 1° and N ≤ 65536.
    pub const MAX_LEVEL: u32 = 30;

    /// A tiling with level-0 delta `D0` (must divide 180°) and `N` samples per side.
    pub fn new(level0_delta_deg: f64, samples: u32) -> Result<Self, GridError> {
        let rows0 = 180.0 / level0_delta_deg;
        if !(1.0..=180.0).contains(&level0_delta_deg) || (rows0 - rows0.round()).abs() > 1e-9 {
            return Err(GridError::BadDelta(level0_delta_deg));
        }
        if !(2..=MAX_TILE_SAMPLES).contains(&samples) {
            return Err(GridError::BadSamples(samples));
        }
        Ok(TileGrid { level0_delta_deg, samples })
    }

    /// Level-0 tile delta, degrees.
    pub fn level0_delta_deg(&self) -> f64 {
        self.level0_delta_deg
    }

    /// Samples per tile side (without halo).
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Tile delta on `level`, degrees.
    pub fn tile_delta_deg(&self, level: u32) -> f64 {
        self.level0_delta_deg / (1u64 << level) as f64
    }

    /// Sample spacing on `level`, degrees.
    pub fn spacing_deg(&self, level: u32) -> f64 {
        self.level0_delta_deg / ((1u64 << level) as f64 * (self.samples - 1) as f64)
    }

    /// Rows and columns of tiles on `level`.
    pub fn tiles_on_level(&self, level: u32) -> (u64, u64) {
        let rows0 = (180.0 / self.level0_delta_deg).round() as u64;
        (rows0 << level, (2 * rows0) << level)
    }

    /// Checks that the tile exists.
    pub fn check(&self, tile: TileId) -> Result<(), GridError> {
        if tile.level > Self::MAX_LEVEL {
            return Err(GridError::LevelTooDeep { level: tile.level, max: Self::MAX_LEVEL });
        }
        let (rows, cols) = self.tiles_on_level(tile.level);
        if tile.row >= rows || tile.col >= cols {
            return Err(GridError::NoSuchTile { level: tile.level, row: tile.row, col: tile.col, rows, cols });
        }
        Ok(())
    }

    /// The sector a tile covers (its outer samples lie on these edges).
    pub fn sector(&self, tile: TileId) -> Sector {
        let d = self.tile_delta_deg(tile.level);
        Sector {
            min_lat: -90.0 + tile.row as f64 * d,
            max_lat: -90.0 + (tile.row + 1) as f64 * d,
            min_lon: -180.0 + tile.col as f64 * d,
            max_lon: -180.0 + (tile.col + 1) as f64 * d,
        }
    }

    /// The tile on `level` that contains a point (points on a shared edge
    /// belong to the tile north/east of it; the north pole and +180° to the last
    /// row/column).
    pub fn tile_containing(&self, lon_deg: f64, lat_deg: f64, level: u32) -> TileId {
        let d = self.tile_delta_deg(level);
        let (rows, cols) = self.tiles_on_level(level);
        let row = (((lat_deg + 90.0) / d).floor().max(0.0) as u64).min(rows - 1);
        let col = (((lon_deg + 180.0) / d).floor().max(0.0) as u64).min(cols - 1);
        TileId::new(level, row, col)
    }

    /// The tiles of `level` that hold some of `b` (which may reach past
    /// ±180°: then those on each side of the antimeridian), row by row.
    pub fn tiles_over(&self, b: &BBox, level: u32) -> Vec<TileId> {
        let parts = b.clipped_to(&BBox::WORLD).into_iter();
        let tiles = parts.flat_map(|p| {
            let (a, z) = (self.tile_containing(p.west, p.south, level), self.tile_containing(p.east, p.north, level));
            (a.row..=z.row).flat_map(move |row| (a.col..=z.col).map(move |col| TileId::new(level, row, col)))
        });
        tiles.collect()
    }

    /// The sample lattice of a tile with `halo` extra samples per side:
    /// `(N + 2B)²` samples, row 0 at the north.
    pub fn tile_samples(&self, tile: TileId, halo: usize) -> SampleGrid {
        let n1 = (self.samples - 1) as i64;
        let len = self.samples as usize + 2 * halo;
        let top = (tile.row as i64 + 1) * n1 + halo as i64;
        self.lattice_window(tile.level, (tile.col as i64 * n1 - halo as i64, top), (len, len))
    }

    /// `width × height` samples of a level's lattice, the north-west one at
    /// global column `gx` and row `top` (counted north from the south pole).
    fn lattice_window(&self, level: u32, (gx, top): (i64, i64), (width, height): (usize, usize)) -> SampleGrid {
        let step = self.spacing_deg(level);
        SampleGrid { lon: Axis::degrees(-180.0, step, gx, width), lat: Axis::degrees(-90.0, -step, -top, height) }
    }

    /// A grid whose samples are lattice points, as the lattice computes
    /// them (the same positions to float rounding, but the very ones the
    /// tiles have, so its values are the tiles' to the bit); `None` if some
    /// sample is not one.
    pub fn on_lattice(&self, grid: &SampleGrid) -> Option<SampleGrid> {
        let (level, gx, top) = self.lattice_position(grid)?;
        Some(self.lattice_window(level, (gx, top), (grid.width(), grid.height())))
    }

    /// Where a grid's samples fall on a level's lattice: the level and the
    /// global column and row index (counted north from the south pole) of its
    /// north-west sample, if every sample is a lattice point.
    pub fn lattice_position(&self, grid: &SampleGrid) -> Option<(u32, i64, i64)> {
        let (lon, lat) = (grid.lon, grid.lat);
        if lon.mapping != lattice::Mapping::Degrees || lat.mapping != lattice::Mapping::Degrees {
            return None;
        }
        let level = self.level_of_spacing(lon.step)?;
        let s = self.spacing_deg(level);
        let index = |v: f64| {
            let i = v / s;
            ((i - i.round()).abs() < 1e-6).then_some(i.round() as i64)
        };
        ((lat.step + s).abs() < 1e-9 * s).then_some(())?;
        Some((level, index(lon.coord(0) + 180.0)?, index(lat.coord(0) + 90.0)?))
    }

    /// The tile whose samples (without halo) a grid is, if it is one.
    pub fn tile_of(&self, grid: &SampleGrid) -> Option<TileId> {
        let n = self.samples as usize;
        let (level, gx, top) = self.lattice_position(grid)?;
        let n1 = (n - 1) as i64;
        let whole = grid.width() == n && grid.height() == n && gx.rem_euclid(n1) == 0 && top.rem_euclid(n1) == 0;
        let id = TileId::new(level, u64::try_from(top / n1 - 1).ok()?, u64::try_from(gx / n1).ok()?);
        (whole && self.check(id).is_ok()).then_some(id)
    }

    /// The level whose lattice has spacing `step_deg`, if any (relative
    /// tolerance 1e-9).
    pub fn level_of_spacing(&self, step_deg: f64) -> Option<u32> {
        (0..=Self::MAX_LEVEL).find(|&l| ((step_deg - self.spacing_deg(l)) / self.spacing_deg(l)).abs() < 1e-9)
    }
}

/// A lat/lon bounding box as given on a command line or in a request.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BBox {
    /// West, degrees.
    pub west: f64,
    /// South, degrees.
    pub south: f64,
    /// East, degrees (may exceed 180 for a box across the antimeridian).
    pub east: f64,
    /// North, degrees.
    pub north: f64,
}

impl BBox {
    /// Every longitude and latitude.
    pub const WORLD: BBox = BBox { west: -180.0, south: -90.0, east: 180.0, north: 90.0 };

    /// Parses `W,S,E,N`.
    pub fn parse(text: &str) -> Result<BBox, GridError> {
        let v: Vec<f64> = text
            .split(',')
            .map(|p| p.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| GridError::BadBBox(format!("{text:?}: {e}")))?;
        let [west, south, east, north] = v[..] else {
            return Err(GridError::BadBBox(format!("{text:?}: expected four numbers W,S,E,N")));
        };
        BBox { west, south, east, north }.checked()
    }

    /// The box as longitudes within −180…180 can say it: itself, turned by
    /// 360° where it lies wholly past ±180°, or every longitude where it
    /// crosses the antimeridian (what WMS capabilities and TileJSON allow).
    pub fn on_the_globe(&self) -> BBox {
        let turn = if self.west >= 180.0 {
            -360.0
        } else if self.east <= -180.0 {
            360.0
        } else {
            0.0
        };
        let (west, east) = (self.west + turn, self.east + turn);
        match west >= -180.0 && east <= 180.0 {
            true => BBox { west, east, ..*self },
            false => BBox { west: -180.0, east: 180.0, ..*self },
        }
    }

    /// The parts of `self` within `bounds`: the box as it is and turned a
    /// world east and west (a box may reach across the antimeridian), each
    /// clipped to `bounds` and in its longitudes, parts that meet joined.
    pub fn clipped_to(&self, bounds: &BBox) -> Vec<BBox> {
        let part = |turn: f64| BBox {
            west: (self.west + turn).max(bounds.west),
            south: self.south.max(bounds.south),
            east: (self.east + turn).min(bounds.east),
            north: self.north.min(bounds.north),
        };
        let mut parts: Vec<BBox> =
            [0.0, -360.0, 360.0].into_iter().map(part).filter(|c| c.west < c.east && c.south < c.north).collect();
        parts.sort_by(|a, b| a.west.total_cmp(&b.west));
        parts.into_iter().fold(Vec::new(), |mut joined: Vec<BBox>, p| {
            match joined.last_mut() {
                Some(last) if last.east >= p.west => last.east = last.east.max(p.east),
                _ => joined.push(p),
            }
            joined
        })
    }

    /// The box turned by whole worlds so that its west lies in −180…180.
    pub fn turned_home(&self) -> BBox {
        let turn = -360.0 * ((self.west + 180.0) / 360.0).floor();
        BBox { west: self.west + turn, east: self.east + turn, ..*self }
    }

    /// The same box as a sector.
    pub fn sector(&self) -> Sector {
        Sector { min_lat: self.south, max_lat: self.north, min_lon: self.west, max_lon: self.east }
    }

    /// True if the two boxes share a point, their longitudes taken modulo
    /// 360° (a box may reach past the antimeridian, up to ±540°).
    pub fn meets(&self, other: &BBox) -> bool {
        let lat = self.south <= other.north && other.south <= self.north;
        // This box turned by whole worlds to start at most 360° west of the other.
        let turn = 360.0 * ((other.west - self.west) / 360.0).floor();
        lat && [0.0, 360.0].iter().any(|t| self.west + turn + t <= other.east && other.west <= self.east + turn + t)
    }

    /// Validates the box: finite, west < east ≤ west + 360, −90 ≤ south < north ≤ 90.
    pub fn checked(self) -> Result<BBox, GridError> {
        let BBox { west, south, east, north } = self;
        if let Some(bad) = [west, south, east, north].into_iter().find(|v| !v.is_finite()) {
            return Err(GridError::BadBBox(format!("{bad}: need finite degrees")));
        }
        if !(-540.0..=540.0).contains(&west) || !(-540.0..=540.0).contains(&east) {
            return Err(GridError::BadBBox("need longitudes within ±540 (W,S,E,N in degrees)".into()));
        }
        if west >= east || east - west > 360.0 {
            return Err(GridError::BadBBox(format!("west {west}, east {east}: need west < east ≤ west + 360")));
        }
        if !((-90.0..=90.0).contains(&south) && south < north && north <= 90.0) {
            return Err(GridError::BadBBox(format!("south {south}, north {north}: need -90 ≤ south < north ≤ 90")));
        }
        Ok(self)
    }

    /// The point-registered grid of `width × height` samples whose outer
    /// samples lie on the box edges (as tiles do). When the box and spacing fall
    /// on a level's lattice, the grid *is* that lattice, so it reproduces tiles
    /// bitwise. A size of 1 puts the sample at the box centre.
    pub fn point_grid(&self, width: usize, height: usize, tiles: &TileGrid) -> Result<SampleGrid, GridError> {
        check_size(width, height)?;
        let lon = point_axis(self.west, self.east, width, 1.0, tiles);
        let lat = point_axis(self.north, self.south, height, -1.0, tiles);
        match (lon, lat) {
            (Some(lon), Some(lat)) if lon.step == -lat.step && lon.origin == -180.0 && lat.origin == -90.0 => {
                Ok(SampleGrid { lon, lat })
            }
            _ => Ok(SampleGrid {
                lon: free_axis(self.west, self.east, width, 1.0),
                lat: free_axis(self.north, self.south, height, -1.0),
            }),
        }
    }

    /// The grid of pixel centres of a `width × height` image covering the box
    /// (WMS GetMap semantics: pixels are areas, the box is their outer edge).
    pub fn area_grid(&self, width: usize, height: usize) -> Result<SampleGrid, GridError> {
        check_size(width, height)?;
        let dx = (self.east - self.west) / width as f64;
        let dy = (self.north - self.south) / height as f64;
        Ok(SampleGrid {
            lon: Axis::degrees(self.west + 0.5 * dx, dx, 0, width),
            lat: Axis::degrees(self.north - 0.5 * dy, -dy, 0, height),
        })
    }
}

/// Largest side of a single request; 4097² float planes are ~67 MB each.
pub const MAX_REQUEST_SIDE: usize = 8193;

/// Most samples per tile side: a tile with its halo stays a request
/// ([`MAX_REQUEST_SIDE`]).
pub const MAX_TILE_SAMPLES: u32 = 4097;

pub(crate) fn check_size(width: usize, height: usize) -> Result<(), GridError> {
    let bad = |reason: &str| GridError::BadSize { width, height, reason: reason.into() };
    if width == 0 || height == 0 {
        return Err(bad("must be at least 1×1"));
    }
    if width > MAX_REQUEST_SIDE || height > MAX_REQUEST_SIDE {
        return Err(bad(&format!("each side must be at most {MAX_REQUEST_SIDE}")));
    }
    Ok(())
}

/// The lattice axis from `a` to `b` (inclusive) if they and the spacing fall on
/// some level's lattice.
fn point_axis(a: f64, b: f64, len: usize, sign: f64, tiles: &TileGrid) -> Option<Axis> {
    if len < 2 {
        return None;
    }
    let level = tiles.level_of_spacing((b - a).abs() / (len - 1) as f64)?;
    let step = tiles.spacing_deg(level);
    let origin = if sign > 0.0 { -180.0 } else { -90.0 };
    let index = (a - origin) / step;
    ((index - index.round()).abs() < 1e-6)
        .then(|| Axis::degrees(origin, sign * step, (sign * index.round()) as i64, len))
}

fn free_axis(a: f64, b: f64, len: usize, sign: f64) -> Axis {
    if len == 1 {
        return Axis::degrees(0.5 * (a + b), sign * (b - a).abs(), 0, len);
    }
    Axis::degrees(a, sign * (b - a).abs() / (len - 1) as f64, 0, len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn boxes_meet_modulo_a_world() {
        let b = |w: f64, e: f64| BBox { west: w, south: 0.0, east: e, north: 1.0 };
        assert!(b(530.0, 540.0).meets(&b(-180.0, -179.0)), "540° is -180°");
        assert!(b(-10.0, 10.0).meets(&b(350.0, 355.0)) && b(350.0, 355.0).meets(&b(-10.0, 10.0)));
        assert!(b(370.0, 371.0).meets(&b(10.5, 12.0)));
        assert!(!b(0.0, 1.0).meets(&b(2.0, 3.0)) && !b(362.0, 363.0).meets(&b(0.0, 1.0)));
        assert!(!b(0.0, 1.0).meets(&BBox { west: 0.0, south: 2.0, east: 1.0, north: 3.0 }));
    }

    #[test]
    fn boxes_on_the_globe_keep_within_a_world() {
        let b = |w: f64, e: f64| BBox { west: w, south: 0.0, east: e, north: 1.0 };
        assert_eq!(b(10.0, 11.0).on_the_globe(), b(10.0, 11.0));
        assert_eq!(b(180.5, 181.5).on_the_globe(), b(-179.5, -178.5));
        assert_eq!(b(-181.0, -180.0).on_the_globe(), b(179.0, 180.0));
        assert_eq!(b(179.5, 180.5).on_the_globe(), b(-180.0, 180.0), "across the antimeridian: every longitude");
    }

    fn grids() -> impl Strategy<Value = TileGrid> {
        (prop::sample::select(vec![36.0, 20.0, 10.0, 180.0]), prop::sample::select(vec![2u32, 3, 65, 150, 513]))
            .prop_map(|(d, n)| TileGrid::new(d, n).unwrap())
    }

    fn tile_on(grid: TileGrid, level: u32, fr: f64, fc: f64) -> TileId {
        let (rows, cols) = grid.tiles_on_level(level);
        TileId::new(level, ((rows as f64 * fr) as u64).min(rows - 1), ((cols as f64 * fc) as u64).min(cols - 1))
    }

    proptest! {
        #[test]
        fn tile_of_a_sector_centre_round_trips(grid in grids(), level in 0u32..=24, fr in 0.0..1.0f64, fc in 0.0..1.0f64) {
            let t = tile_on(grid, level, fr, fc);
            let s = grid.sector(t);
            let back = grid.tile_containing(0.5 * (s.min_lon + s.max_lon), 0.5 * (s.min_lat + s.max_lat), level);
            prop_assert_eq!(back, t);
            prop_assert!(t.children().iter().all(|c| c.parent() == Some(t)));
        }

        #[test]
        fn neighbours_share_their_edge_samples_bitwise(grid in grids(), level in 0u32..=24, fr in 0.0..1.0f64, fc in 0.0..1.0f64, halo in 0usize..40) {
            let t = tile_on(grid, level, fr, fc);
            let (rows, cols) = grid.tiles_on_level(level);
            let n = grid.samples() as usize;
            let g = grid.tile_samples(t, halo);
            if t.col + 1 < cols {
                let east = grid.tile_samples(TileId::new(level, t.row, t.col + 1), halo);
                prop_assert_eq!(g.lon.coord(halo + n - 1).to_bits(), east.lon.coord(halo).to_bits());
                // The halo of one tile is the other tile's lattice.
                prop_assert_eq!(g.lon.coord(halo + n).to_bits(), east.lon.coord(halo + 1).to_bits());
            }
            if t.row + 1 < rows {
                let north = grid.tile_samples(TileId::new(level, t.row + 1, t.col), halo);
                prop_assert_eq!(g.lat.coord(halo).to_bits(), north.lat.coord(halo + n - 1).to_bits());
            }
            let s = grid.sector(t);
            prop_assert!((g.lon.coord(halo) - s.min_lon).abs() < 1e-9);
            prop_assert!((g.lat.coord(halo) - s.max_lat).abs() < 1e-9);
        }

        #[test]
        fn levels_nest_and_parent_samples_are_child_samples(grid in grids(), level in 0u32..=23, fr in 0.0..1.0f64, fc in 0.0..1.0f64) {
            let t = tile_on(grid, level, fr, fc);
            let s = grid.sector(t);
            let kids: Vec<Sector> = t.children().iter().map(|&c| grid.sector(c)).collect();
            let area: f64 = kids.iter().map(|k| (k.max_lat - k.min_lat) * (k.max_lon - k.min_lon)).sum();
            prop_assert!((area - (s.max_lat - s.min_lat) * (s.max_lon - s.min_lon)).abs() < 1e-9 * area.max(1e-300));
            prop_assert!(kids.iter().all(|k| k.min_lat >= s.min_lat && k.max_lat <= s.max_lat && k.min_lon >= s.min_lon && k.max_lon <= s.max_lon));
            let parent = grid.tile_samples(t, 0);
            let sw = grid.tile_samples(t.children()[0], 0);
            // Parent sample i is child sample 2i (the south-west child holds the west half).
            let n = grid.samples() as usize;
            for i in 0..n.div_ceil(2) {
                prop_assert_eq!(parent.lon.coord(i).to_bits(), sw.lon.coord(2 * i).to_bits());
            }
        }

        #[test]
        fn a_build_box_on_the_lattice_reproduces_tile_coordinates(level in 0u32..=22, fr in 0.0..1.0f64, fc in 0.0..1.0f64) {
            let grid = TileGrid::new(36.0, 65).unwrap();
            let t = tile_on(grid, level, fr, fc);
            let s = grid.sector(t);
            let bbox = s.bbox();
            let built = bbox.point_grid(65, 65, &grid).unwrap();
            prop_assert_eq!(built, grid.tile_samples(t, 0));
        }
    }

    #[test]
    fn grids_on_the_lattice_are_recognised() {
        let g = TileGrid::new(36.0, 65).unwrap();
        let t = TileId::new(7, 100, 300);
        let samples = g.tile_samples(t, 0);
        assert_eq!(g.tile_of(&samples), Some(t));
        assert_eq!(g.tile_of(&g.tile_samples(t, 2)), None);
        let (level, gx, top) = g.lattice_position(&g.tile_samples(t, 2)).unwrap();
        assert_eq!((level, gx, top), (7, 300 * 64 - 2, 101 * 64 + 2));
        // A WMS grid whose pixel centres are the tile's samples.
        let s = g.sector(t);
        let d = g.spacing_deg(7) / 2.0;
        let wms = BBox { west: s.min_lon - d, south: s.min_lat - d, east: s.max_lon + d, north: s.max_lat + d }
            .area_grid(65, 65)
            .unwrap();
        assert_eq!(g.tile_of(&wms), Some(t));
        assert_eq!(g.tile_of(&BBox::parse("0,0,1,1").unwrap().area_grid(65, 65).unwrap()), None);
    }

    #[test]
    fn bad_parameters_are_refused_with_reasons() {
        assert_eq!(TileGrid::new(7.0, 513), Err(GridError::BadDelta(7.0)));
        assert_eq!(TileGrid::new(36.0, 1), Err(GridError::BadSamples(1)));
        assert_eq!(TileGrid::new(36.0, 65536), Err(GridError::BadSamples(65536)));
        let g = TileGrid::new(36.0, 513).unwrap();
        assert!(matches!(g.check(TileId::new(0, 5, 0)), Err(GridError::NoSuchTile { .. })));
        assert!(g.check(TileId::new(22, 5 * (1 << 22) - 1, 10 * (1 << 22) - 1)).is_ok());
        assert!(BBox::parse("1,2,3").is_err());
        assert!(BBox::parse("10,0,5,1").is_err());
        assert!(BBox::parse("0,-91,1,0").is_err());
        assert!(BBox::parse("170,0,190,1").is_ok());
        let b = BBox::parse("0,0,1,1").unwrap();
        assert!(b.point_grid(0, 5, &g).is_err());
        assert!(b.point_grid(4097, 4097, &g).is_ok());
    }

    #[test]
    fn one_by_one_requests_sample_the_centre() {
        let g = TileGrid::new(36.0, 513).unwrap();
        let grid = BBox::parse("10,20,11,22").unwrap().point_grid(1, 1, &g).unwrap();
        assert_eq!(grid.lon_lat(0, 0), (10.5, 21.0));
        assert!(grid.spacing_deg() > 0.0);
    }

    #[test]
    fn wms_grids_sample_pixel_centres() {
        let grid = BBox::parse("0,0,4,2").unwrap().area_grid(4, 2).unwrap();
        assert_eq!(grid.lon.coords(), vec![0.5, 1.5, 2.5, 3.5]);
        assert_eq!(grid.lat.coords(), vec![1.5, 0.5]);
    }

    #[test]
    fn a_bad_box_names_its_fault() {
        for (text, fault) in [
            ("179.8,-16.6,180.2,nan", "NaN: need finite degrees"),
            ("0,0,1,inf", "inf: need finite degrees"),
            ("-600,-17,-599,-16", "need longitudes within ±540"),
            ("1e300,0,2e300,1", "need longitudes within ±540"),
            ("2,0,1,1", "need west < east"),
            ("0,1,1,0", "need -90 ≤ south < north ≤ 90"),
        ] {
            let err = BBox::parse(text).unwrap_err().to_string();
            assert!(err.contains(fault) && err.len() < 200, "{text}: {err}");
        }
    }

    #[test]
    fn a_box_is_clipped_to_bounds_on_both_sides_of_the_antimeridian() {
        let region = BBox { west: 10.0, south: 46.3, east: 10.25, north: 46.45 };
        let world = BBox::WORLD;
        assert_eq!(world.clipped_to(&region), [region]);
        let part = BBox { west: 10.1, south: 40.0, east: 20.0, north: 46.4 };
        assert_eq!(part.clipped_to(&region), [BBox { west: 10.1, south: 46.3, east: 10.25, north: 46.4 }]);
        assert_eq!(BBox { west: 11.0, south: 46.3, east: 12.0, north: 46.4 }.clipped_to(&region), []);
        // Across the antimeridian, from 170° E to 170° W, over a region at 175° W.
        let pacific = BBox { west: -176.0, south: -20.0, east: -174.0, north: -18.0 };
        let across = BBox { west: 170.0, south: -30.0, east: 190.0, north: 0.0 };
        assert_eq!(across.clipped_to(&pacific), [pacific]);
        // Over a region on both sides: two parts.
        let both = across.clipped_to(&world);
        assert_eq!(both.len(), 2, "{both:?}");
        // A region across the antimeridian: the world is one part of it, and
        // a box west of 180° the part past 180° in the region's longitudes.
        let fiji = BBox { west: 179.5, south: -17.0, east: 180.5, north: -16.0 };
        assert_eq!(world.clipped_to(&fiji), [fiji]);
        let west = BBox { west: -180.0, south: -17.0, east: -179.5, north: -16.0 };
        assert_eq!(west.clipped_to(&fiji), [BBox { west: 180.0, ..fiji }]);
        let far = BBox { west: 539.6, south: -17.0, east: 540.2, north: -16.0 };
        let home = far.turned_home();
        assert!((home.west - 179.6).abs() < 1e-9 && (home.east - 180.2).abs() < 1e-9, "{home:?}");
        assert_eq!(fiji.turned_home(), fiji);
    }
}
