//! Sample lattices: the lat/lon position of every sample of a tile or request.
//!
//! A coordinate is always computed as `origin + (index as f64) * step` from an
//! integer index, never by accumulation. Tiles and whole-area builds on the same
//! level share origin (−180°, −90°), step and integer indices, so a sample has
//! bitwise the same coordinate whichever request computes it — the root of the
//! seamless-tile invariant.

/// One axis of a sample grid: `coord(i) = origin + (first + i) · step`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Axis {
    /// Coordinate of index 0, degrees.
    pub origin: f64,
    /// Degrees between neighbouring samples (negative for latitude rows, which
    /// run north to south).
    pub step: f64,
    /// Index of the first sample.
    pub first: i64,
    /// Number of samples.
    pub len: usize,
}

impl Axis {
    /// Coordinate of sample `i`, degrees.
    #[inline]
    pub fn coord(&self, i: usize) -> f64 {
        self.origin + (self.first + i as i64) as f64 * self.step
    }

    /// Coordinate of a possibly fractional or out-of-range position.
    pub fn coord_at(&self, i: f64) -> f64 {
        self.origin + (self.first as f64 + i) * self.step
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
        self.lon.step.abs().max(self.lat.step.abs())
    }

    /// Sample spacing in metres on the ground (east–west spacing shrinks with
    /// the cosine of the latitude; the larger of the two is returned).
    pub fn spacing_m(&self) -> f64 {
        let mid_lat = self.lat.coord_at((self.lat.len as f64 - 1.0) / 2.0).clamp(-90.0, 90.0);
        let east = self.lon.step.abs() * mid_lat.to_radians().cos();
        east.max(self.lat.step.abs()) * crate::geo::METRES_PER_DEGREE
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
        let (gx, gy) = (self.lon.first + x, self.lat.first + y);
        match (self.lon.period(360.0, -180.0), self.lat.period(360.0, -90.0)) {
            (Some(around), Some(_)) => {
                // Latitude index counted north from the south pole.
                let mut north = gy * self.lat.step.signum() as i64;
                let pole = around / 2;
                let mut east = gx;
                if north > pole || north < 0 {
                    north = if north > pole { 2 * pole - north } else { -north };
                    east += around / 2;
                }
                let east = east.rem_euclid(around);
                (-180.0 + east as f64 * self.lon.step, -90.0 + north as f64 * self.lat.step.abs())
            }
            _ => crate::geo::normalize(self.lon.coord_at(x as f64), self.lat.coord_at(y as f64)),
        }
    }
}

impl Axis {
    /// Samples per `span` degrees when this axis is on a global lattice with
    /// that origin and a whole (even) number of samples in the span.
    fn period(&self, span: f64, origin: f64) -> Option<i64> {
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
        let a = Axis { origin: -180.0, step: 0.1, first: 37, len: 10 };
        let g = a.grown(3);
        assert_eq!(g.coord(3).to_bits(), a.coord(0).to_bits());
        assert_eq!(a.slice(-3, 16), g);
        assert_eq!(g.len, 16);
    }

    #[test]
    fn positions_across_the_antimeridian_and_the_poles_are_exact() {
        let s = 0.25;
        let grid = SampleGrid {
            lon: Axis { origin: -180.0, step: s, first: -2, len: 5 },
            lat: Axis { origin: -90.0, step: -s, first: -(4 * 180 + 2), len: 5 },
        };
        // Two samples west of −180° are the last two of the globe.
        assert_eq!(grid.on_globe(0, 2).0.to_bits(), (-180.0f64 + 1438.0 * s).to_bits());
        assert_eq!(grid.on_globe(2, 2), (-180.0, 90.0));
        // Two rows north of the pole: 89.5° on the opposite meridian.
        assert_eq!(grid.on_globe(2, 0), (0.0, 89.5));
        let free = SampleGrid {
            lon: Axis { origin: 179.9, step: 0.3, first: 0, len: 2 },
            lat: Axis { origin: 10.0, step: -1.0, first: 0, len: 1 },
        };
        assert!((free.on_globe(1, 0).0 - (-179.8)).abs() < 1e-9);
    }

    #[test]
    fn latitude_rows_run_north_to_south() {
        let lat = Axis { origin: -90.0, step: -0.5, first: -20, len: 3 };
        assert_eq!(lat.coords(), vec![-80.0, -80.5, -81.0]);
    }
}
