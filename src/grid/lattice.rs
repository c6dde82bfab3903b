//! Sample lattices: the lat/lon position of every sample of a tile or request.
//!
//! A coordinate is always computed as `origin + (index as f64) * step` from an
//! integer index, never by accumulation. Tiles and whole-area builds on the same
//! level share origin (−180°, −90°), step and integer indices, so a sample has
//! bitwise the same coordinate whichever request computes it — the root of the
//! seamless-tile invariant.
//!
//! An axis is regular either in degrees (EPSG:4326 requests and tiles) or in
//! Web Mercator metres (EPSG:3857 requests, XYZ tiles); in the latter case
//! `origin` and `step` are metres and [`Axis::coord`] converts to degrees.

/// Equatorial radius of the WGS84 ellipsoid, the sphere of Web Mercator.
pub const MERCATOR_RADIUS_M: f64 = 6_378_137.0;

/// What an axis's regular values are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mapping {
    /// Degrees of longitude or latitude.
    Degrees,
    /// Web Mercator x, metres (longitude is linear in it).
    MercatorX,
    /// Web Mercator y, metres (latitude by the inverse Gudermannian).
    MercatorY,
}

/// One axis of a sample grid: `value(i) = origin + (first + i) · step`,
/// mapped to degrees by `mapping`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Axis {
    /// Value of index 0 (degrees, or metres for Mercator axes).
    pub origin: f64,
    /// Value between neighbouring samples (negative for rows, which run
    /// north to south).
    pub step: f64,
    /// Index of the first sample.
    pub first: i64,
    /// Number of samples.
    pub len: usize,
    /// Degrees or Web Mercator metres.
    pub mapping: Mapping,
}

impl Axis {
    /// An axis regular in degrees.
    pub fn degrees(origin: f64, step: f64, first: i64, len: usize) -> Axis {
        Axis { origin, step, first, len, mapping: Mapping::Degrees }
    }

    /// Coordinate of sample `i`, degrees.
    #[inline]
    pub fn coord(&self, i: usize) -> f64 {
        self.degrees_of(self.origin + (self.first + i as i64) as f64 * self.step)
    }

    /// Coordinate of a possibly fractional or out-of-range position, degrees.
    pub fn coord_at(&self, i: f64) -> f64 {
        self.degrees_of(self.origin + (self.first as f64 + i) * self.step)
    }

    /// The regular value (degrees or metres) of sample `i`.
    pub fn value(&self, i: usize) -> f64 {
        self.origin + (self.first + i as i64) as f64 * self.step
    }

    #[inline]
    fn degrees_of(&self, v: f64) -> f64 {
        match self.mapping {
            Mapping::Degrees => v,
            Mapping::MercatorX => (v / MERCATOR_RADIUS_M).to_degrees(),
            Mapping::MercatorY => (v / MERCATOR_RADIUS_M).sinh().atan().to_degrees(),
        }
    }

    /// Degrees between samples (for Mercator axes, at the axis's middle):
    /// what decides overview levels and canopy filtering.
    pub fn step_deg(&self) -> f64 {
        let mid = (self.len as f64 - 1.0) / 2.0;
        match self.mapping {
            Mapping::Degrees => self.step.abs(),
            _ => (self.coord_at(mid + 0.5) - self.coord_at(mid - 0.5)).abs(),
        }
    }

    /// Degrees between the midpoints around sample `i`: the local spacing,
    /// the same (bitwise) for a sample's global index in any grid on this
    /// axis.
    pub fn step_deg_at(&self, i: usize) -> f64 {
        match self.mapping {
            Mapping::Degrees => self.step.abs(),
            _ => (self.coord_at(i as f64 + 0.5) - self.coord_at(i as f64 - 0.5)).abs(),
        }
    }

    /// The axis grown by `margin` samples at both ends.
    pub fn grown(&self, margin: usize) -> Axis {
        Axis { first: self.first - margin as i64, len: self.len + 2 * margin, ..*self }
    }

    /// The sub-axis of `len` samples starting at sample `start` (may be negative).
    pub fn slice(&self, start: i64, len: usize) -> Axis {
        Axis { first: self.first + start, len, ..*self }
    }

    /// All coordinates.
    pub fn coords(&self) -> Vec<f64> {
        (0..self.len).map(|i| self.coord(i)).collect()
    }
}

/// A regular grid of samples in geographic coordinates (EPSG:4326), row 0 at
/// the north.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleGrid {
    /// Longitudes of the columns.
    pub lon: Axis,
    /// Latitudes of the rows (negative step).
    pub lat: Axis,
}

impl SampleGrid {
    /// Number of columns.
    pub fn width(&self) -> usize {
        self.lon.len
    }

    /// Number of rows.
    pub fn height(&self) -> usize {
        self.lat.len
    }

    /// The grid grown by `margin` samples on every side.
    pub fn grown(&self, margin: usize) -> SampleGrid {
        SampleGrid { lon: self.lon.grown(margin), lat: self.lat.grown(margin) }
    }

    /// The sub-grid of `width × height` samples starting at column `x`, row `y`.
    pub fn slice(&self, x: i64, y: i64, width: usize, height: usize) -> SampleGrid {
        SampleGrid { lon: self.lon.slice(x, width), lat: self.lat.slice(y, height) }
    }

    /// Sample spacing in degrees: the larger of the two axes.
    pub fn spacing_deg(&self) -> f64 {
        self.lon.step_deg().max(self.lat.step_deg())
    }

    /// Sample spacing in metres on the ground (east–west spacing shrinks with
    /// the cosine of the latitude; the larger of the two is returned).
    pub fn spacing_m(&self) -> f64 {
        let mid_lat = self.lat.coord_at((self.lat.len as f64 - 1.0) / 2.0).clamp(-90.0, 90.0);
        let east = self.lon.step_deg() * mid_lat.to_radians().cos();
        east.max(self.lat.step_deg()) * crate::geo::METRES_PER_DEGREE
    }

    /// The `(lon, lat)` of sample `(x, y)`, exactly as computed from the
    /// lattice (not normalised: halos may reach past ±180° or ±90°).
    pub fn lon_lat(&self, x: usize, y: usize) -> (f64, f64) {
        (self.lon.coord(x), self.lat.coord(y))
    }

    /// The position on the globe of sample `(x, y)` — which may lie outside
    /// the grid — with latitudes past a pole reflected onto the opposite
    /// meridian and longitudes wrapped into `[-180, 180)`.
    ///
    /// On a global lattice (origin −180°/−90°, a whole number of samples
    /// around the globe) this is done on the integer indices, so a sample
    /// reached across the antimeridian or a pole has bitwise the coordinate it
    /// has on the other side.
    pub fn on_globe(&self, x: i64, y: i64) -> (f64, f64) {
        self.globe().at(x, y)
    }

    /// [`SampleGrid::on_globe`] with the lattice's periods worked out once,
    /// for callers that place many samples.
    pub fn globe(&self) -> Globe<'_> {
        let periods = match (self.lon.period(360.0, -180.0), self.lat.period(360.0, -90.0)) {
            (Some(around), Some(_)) => Some(around),
            _ => None,
        };
        Globe { grid: self, around: periods }
    }
}

/// Positions on the globe of a grid's samples (see [`SampleGrid::globe`]).
#[derive(Clone, Copy, Debug)]
pub struct Globe<'a> {
    grid: &'a SampleGrid,
    /// Samples around the globe, on a global lattice.
    around: Option<i64>,
}

impl Globe<'_> {
    /// The position of sample `(x, y)`, as [`SampleGrid::on_globe`].
    #[inline]
    pub fn at(&self, x: i64, y: i64) -> (f64, f64) {
        let g = self.grid;
        let Some(around) = self.around else {
            return crate::geo::normalize(g.lon.coord_at(x as f64), g.lat.coord_at(y as f64));
        };
        let (gx, gy) = (g.lon.first + x, g.lat.first + y);
        // Latitude index counted north from the south pole.
        let mut north = gy * g.lat.step.signum() as i64;
        let pole = around / 2;
        let mut east = gx;
        if north > pole || north < 0 {
            north = if north > pole { 2 * pole - north } else { -north };
            east += around / 2;
        }
        // Most samples are on the globe already: skip the division.
        let east = if (0..around).contains(&east) { east } else { east.rem_euclid(around) };
        (-180.0 + east as f64 * g.lon.step, -90.0 + north as f64 * g.lat.step.abs())
    }
}

impl Axis {
    /// Samples per `span` degrees when this axis is on a global lattice with
    /// that origin and a whole (even) number of samples in the span.
    fn period(&self, span: f64, origin: f64) -> Option<i64> {
        if self.mapping != Mapping::Degrees {
            return None;
        }
        let n = span / self.step.abs();
        let whole = n.round();
        (self.origin == origin && (n - whole).abs() < 1e-6 && whole as i64 % 2 == 0 && whole > 0.0)
            .then_some(whole as i64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slices_and_growth_keep_coordinates_bitwise() {
        let a = Axis::degrees(-180.0, 0.1, 37, 10);
        let g = a.grown(3);
        assert_eq!(g.coord(3).to_bits(), a.coord(0).to_bits());
        assert_eq!(a.slice(-3, 16), g);
        assert_eq!(g.len, 16);
    }

    #[test]
    fn positions_across_the_antimeridian_and_the_poles_are_exact() {
        let s = 0.25;
        let grid =
            SampleGrid { lon: Axis::degrees(-180.0, s, -2, 5), lat: Axis::degrees(-90.0, -s, -(4 * 180 + 2), 5) };
        // Two samples west of −180° are the last two of the globe.
        assert_eq!(grid.on_globe(0, 2).0.to_bits(), (-180.0f64 + 1438.0 * s).to_bits());
        assert_eq!(grid.on_globe(2, 2), (-180.0, 90.0));
        // Two rows north of the pole: 89.5° on the opposite meridian.
        assert_eq!(grid.on_globe(2, 0), (0.0, 89.5));
        let free = SampleGrid { lon: Axis::degrees(179.9, 0.3, 0, 2), lat: Axis::degrees(10.0, -1.0, 0, 1) };
        assert!((free.on_globe(1, 0).0 - (-179.8)).abs() < 1e-9);
    }

    #[test]
    fn latitude_rows_run_north_to_south() {
        let lat = Axis::degrees(-90.0, -0.5, -20, 3);
        assert_eq!(lat.coords(), vec![-80.0, -80.5, -81.0]);
    }
}
