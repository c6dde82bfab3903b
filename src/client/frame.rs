//! A tile's local tangent frame: the flat world the ray caster works in.
//!
//! The dissertation (6.4) ray casts a height map over a plane. On the globe
//! each tile gets its own plane: the east-north-up frame at its centre on the
//! WGS84 ellipsoid. Sample `(i, j)` (east, north; `(0, 0)` the south-west
//! corner) sits at `x = (i − c)·sx`, `y = (j − c)·sy` with `c = (N − 1)/2`
//! and `sx`, `sy` the sample spacing in metres at the centre latitude; a
//! height `h` is at `z = h + drop(i, j)`, where `drop` is the (negative)
//! height of the ellipsoid below the tangent plane at that sample. So the map
//! is an affine image of texel space, rays stay straight in it, and heights
//! are exact along the centre's normal.
//!
//! What the flat frame gets wrong is the horizontal position of a sample
//! (the tile is a trapezoid on the ellipsoid, a rectangle here) and the tilt
//! of the local vertical: [`TileFrame::flat_error_m`] bounds both, and the
//! quadtree refines a tile while that error is visible.
//!
//! Positions are `f64`; a frame gives the GPU camera-relative `f32` values.

use super::globe::{self, Geodetic};
use crate::grid::{Sector, TileGrid, TileId};
use glam::{DMat3, DVec2, DVec3};

/// The flat frame of one tile.
#[derive(Clone, Copy, Debug)]
pub struct TileFrame {
    /// The tile.
    pub id: TileId,
    /// Its sector.
    pub sector: Sector,
    /// Samples per side, without halo.
    pub samples: u32,
    /// ECEF position of the frame origin (the sector centre, height 0).
    pub origin_ecef: DVec3,
    /// Local east, north, up as columns (local → ECEF rotation).
    pub basis: DMat3,
    /// Metres per sample east and north.
    pub spacing_m: DVec2,
    lon0_rad: f64,
    lat0_rad: f64,
    spacing_rad: f64,
}

impl TileFrame {
    /// The frame of `id` on `grid`.
    pub fn new(grid: &TileGrid, id: TileId) -> TileFrame {
        let sector = grid.sector(id);
        let lat0 = (sector.min_lat + sector.max_lat) / 2.0;
        let lon0 = (sector.min_lon + sector.max_lon) / 2.0;
        let spacing_rad = grid.spacing_deg(id.level).to_radians();
        let sin_lat = lat0.to_radians().sin();
        let east = globe::prime_vertical_radius_m(sin_lat) * lat0.to_radians().cos();
        let north = globe::meridional_radius_m(sin_lat);
        TileFrame {
            id,
            sector,
            samples: grid.samples(),
            origin_ecef: Geodetic::new(lon0, lat0, 0.0).to_ecef(),
            basis: globe::enu_basis(lon0, lat0),
            spacing_m: DVec2::new(east * spacing_rad, north * spacing_rad),
            lon0_rad: lon0.to_radians(),
            lat0_rad: lat0.to_radians(),
            spacing_rad,
        }
    }

    /// The same frame with its origin moved `base_m` up the centre normal,
    /// so heights near the tile's own can be small numbers.
    pub fn raised(self, base_m: f64) -> TileFrame {
        TileFrame { origin_ecef: self.origin_ecef + self.basis.z_axis * base_m, ..self }
    }

    /// The centre sample index `c = (N − 1)/2`.
    pub fn centre_index(&self) -> f64 {
        (self.samples - 1) as f64 / 2.0
    }

    /// Flat-frame x, y of sample `(i, j)` (fractional and halo indices allowed).
    pub fn local_xy(&self, i: f64, j: f64) -> DVec2 {
        let c = self.centre_index();
        DVec2::new((i - c) * self.spacing_m.x, (j - c) * self.spacing_m.y)
    }

    /// Sample coordinates of a flat-frame x, y.
    pub fn sample_of(&self, xy: DVec2) -> DVec2 {
        xy / self.spacing_m + DVec2::splat(self.centre_index())
    }

    /// Sample coordinates of the point at `(lon, lat)`, degrees, its
    /// longitude taken within half a turn of the tile's.
    pub fn sample_at(&self, lon_deg: f64, lat_deg: f64) -> DVec2 {
        let turn = std::f64::consts::TAU;
        let lon = (lon_deg.to_radians() - self.lon0_rad + turn / 2.0).rem_euclid(turn) - turn / 2.0;
        let lat = lat_deg.to_radians() - self.lat0_rad;
        DVec2::new(lon, lat) / self.spacing_rad + DVec2::splat(self.centre_index())
    }

    /// An ECEF point in the local frame.
    pub fn to_local(&self, p_ecef: DVec3) -> DVec3 {
        self.basis.transpose() * (p_ecef - self.origin_ecef)
    }

    /// A local point in ECEF.
    pub fn to_ecef(&self, local: DVec3) -> DVec3 {
        self.origin_ecef + self.basis * local
    }

    /// The longitude and latitude (radians) of sample `(i, j)`.
    fn lon_lat_rad(&self, i: f64, j: f64) -> (f64, f64) {
        let c = self.centre_index();
        (self.lon0_rad + (i - c) * self.spacing_rad, self.lat0_rad + (j - c) * self.spacing_rad)
    }

    /// The true position, in the local frame, of the ellipsoid point under
    /// sample `(i, j)`.
    pub fn ellipsoid_local(&self, i: f64, j: f64) -> DVec3 {
        let (lon, lat) = self.lon_lat_rad(i, j);
        let p = Geodetic::new(lon.to_degrees(), lat.to_degrees(), 0.0).to_ecef();
        self.to_local(p)
    }

    /// The ellipsoid's unit normal under sample `(i, j)`, in the local frame.
    pub fn normal_local(&self, i: f64, j: f64) -> DVec3 {
        let (lon, lat) = self.lon_lat_rad(i, j);
        self.basis.transpose() * globe::enu_basis(lon.to_degrees(), lat.to_degrees()).z_axis
    }

    /// The drop of the ellipsoid below the tangent plane at every sample of
    /// a `(N + 2·halo)²` block, row 0 at the south: added to heights so that
    /// they are measured from the tangent plane. Separable in latitude and
    /// longitude, so one multiply-add per sample.
    pub fn drops_m(&self, halo: usize) -> Vec<f64> {
        let len = self.samples as usize + 2 * halo;
        let (sin0, cos0) = self.lat0_rad.sin_cos();
        let up_origin = self.basis.z_axis.dot(self.origin_ecef);
        let index = |k: usize| k as f64 - halo as f64;
        // Per row: the ellipsoid's distance from the axis and height over
        // the equator; per column: the cosine of the longitude difference.
        let rows: Vec<(f64, f64)> = (0..len)
            .map(|k| {
                let (_, lat) = self.lon_lat_rad(0.0, index(k));
                let (s, c) = lat.sin_cos();
                let n = globe::prime_vertical_radius_m(s);
                (n * c * cos0, n * (1.0 - globe::E2) * s * sin0)
            })
            .collect();
        let cols: Vec<f64> = (0..len).map(|k| (self.lon_lat_rad(index(k), 0.0).0 - self.lon0_rad).cos()).collect();
        let mut out = Vec::with_capacity(len * len);
        for &(r, z) in &rows {
            out.extend(cols.iter().map(|&c| r * c + z - up_origin));
        }
        out
    }

    /// A bound (metres) on how far the flat frame puts any point of the
    /// tile with heights within ±`max_abs_height_m` from where it is on the
    /// ellipsoid: the horizontal misplacement of the sample lattice, largest
    /// at the corners, plus the tilt of the local vertical at the corners
    /// times the height.
    pub fn flat_error_m(&self, max_abs_height_m: f64) -> f64 {
        let mut worst: f64 = 0.0;
        for (i, j) in self.rim() {
            let truth = self.ellipsoid_local(i, j);
            let flat = self.local_xy(i, j);
            let tilt = self.normal_local(i, j).truncate().length();
            worst = worst.max((truth.truncate() - flat).length() + tilt * max_abs_height_m);
        }
        worst
    }

    /// The largest angle between the ellipsoid's normal and the frame's up
    /// over the tile (largest on its rim), radians.
    pub fn max_tilt_rad(&self) -> f64 {
        self.rim().iter().map(|&(i, j)| self.normal_local(i, j).truncate().length().min(1.0).asin()).fold(0.0, f64::max)
    }

    /// Where the flat frame departs most from the ellipsoid: the tile's
    /// corners and its edges' midpoints, as sample coordinates.
    fn rim(&self) -> [(f64, f64); 8] {
        let n1 = (self.samples - 1) as f64;
        let mid = n1 / 2.0;
        [(0.0, 0.0), (n1, 0.0), (0.0, n1), (n1, n1), (mid, 0.0), (mid, n1), (0.0, mid), (n1, mid)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> TileGrid {
        TileGrid::new(36.0, 513).unwrap()
    }

    #[test]
    fn the_centre_sample_is_the_origin_and_drops_are_the_ellipsoid() {
        let g = grid();
        let f = TileFrame::new(&g, g.tile_containing(10.2, 46.4, 9));
        assert!(f.ellipsoid_local(256.0, 256.0).length() < 1e-6);
        let drops = f.drops_m(2);
        let len = 513 + 4;
        for (i, j) in [(0usize, 0usize), (516, 0), (100, 400), (516, 516)] {
            let exact = f.ellipsoid_local(i as f64 - 2.0, j as f64 - 2.0).z;
            assert!((drops[j * len + i] - exact).abs() < 1e-6, "{} vs {}", drops[j * len + i], exact);
        }
        // A level-9 tile is ~8 km: the corners drop d²/2R ≈ 2.5 m.
        assert!(drops[0] < -1.0 && drops[0] > -10.0, "{}", drops[0]);
    }

    #[test]
    fn the_flat_error_shrinks_quadratically_with_the_tile() {
        let g = grid();
        let e = |level| TileFrame::new(&g, g.tile_containing(10.2, 46.4, level)).flat_error_m(0.0);
        let (e8, e10) = (e(8), e(10));
        // Four times smaller per level (second order in the tile size).
        assert!(e10 < e8 / 12.0 && e10 > e8 / 20.0, "{e8} {e10}");
        assert!(e(16) < 1e-3);
    }

    #[test]
    fn local_and_ecef_round_trip() {
        let g = grid();
        let f = TileFrame::new(&g, TileId::new(3, 20, 70));
        let p = DVec3::new(1234.5, -987.25, 4321.0);
        assert!((f.to_local(f.to_ecef(p)) - p).length() < 1e-6);
        let s = f.sample_of(f.local_xy(17.25, 400.5));
        assert!((s - DVec2::new(17.25, 400.5)).length() < 1e-9);
    }
}
