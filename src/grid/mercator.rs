//! Web Mercator (EPSG:3857) request grids and XYZ tile addressing (the
//! "slippy map" scheme of OpenStreetMap, MapLibre and Terrarium tiles: tile
//! (0, 0) at the north-west, `2^z × 2^z` tiles).

use super::lattice::{Axis, MERCATOR_RADIUS_M, Mapping, SampleGrid};
use super::quad::MAX_ZOOM;
use super::{BBox, GridError, check_size};
use std::f64::consts::PI;

/// Half the side of the Web Mercator square, metres.
pub const HALF_WORLD_M: f64 = PI * MERCATOR_RADIUS_M;

/// A box in Web Mercator metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MercatorBox {
    /// West, metres.
    pub west: f64,
    /// South, metres.
    pub south: f64,
    /// East, metres.
    pub east: f64,
    /// North, metres.
    pub north: f64,
}

impl MercatorBox {
    /// Validates the box: finite, west < east at most one world's width
    /// apart (with 1 m of slack for rounding), south < north, each edge
    /// within one and a half worlds' width of the origin (±540°, as a
    /// CRS:84 box). Like a CRS:84 box it may reach past the antimeridian
    /// (longitudes wrap); past the square's north and south edges the
    /// projection still maps it, to within a thousandth of a degree of the
    /// poles.
    pub fn checked(self) -> Result<MercatorBox, GridError> {
        let MercatorBox { west, south, east, north } = self;
        let world = 2.0 * HALF_WORLD_M + 1.0;
        let limit = 1.5 * world;
        let within = [west, south, east, north].iter().all(|v| v.is_finite() && v.abs() <= limit);
        if !within || west >= east || east - west > world || south >= north {
            return Err(GridError::BadBBox(format!(
                "EPSG:3857 box {west},{south},{east},{north}: need west < east ≤ west + {:.0} m, south < north, \
                 each within ±{limit:.0} m",
                2.0 * HALF_WORLD_M
            )));
        }
        Ok(self)
    }

    /// The pixel centres of a `width × height` image over the box.
    pub fn area_grid(&self, width: usize, height: usize) -> Result<SampleGrid, GridError> {
        check_size(width, height)?;
        let dx = (self.east - self.west) / width as f64;
        let dy = (self.north - self.south) / height as f64;
        Ok(SampleGrid {
            lon: Axis { origin: self.west + 0.5 * dx, step: dx, first: 0, len: width, mapping: Mapping::MercatorX },
            lat: Axis { origin: self.north - 0.5 * dy, step: -dy, first: 0, len: height, mapping: Mapping::MercatorY },
        })
    }

    /// The box of XYZ tile `(z, x, y)`, or an error if it does not exist.
    pub fn of_tile(z: u32, x: u64, y: u64) -> Result<MercatorBox, GridError> {
        let n = 1u64 << z.min(MAX_ZOOM);
        if z > MAX_ZOOM || x >= n || y >= n {
            return Err(GridError::NoSuchTile { level: z, row: y, col: x, rows: n, cols: n });
        }
        Ok(MercatorBox::tile(z, x, y))
    }

    /// The box of XYZ tile `(z, x, y)`, assumed to exist.
    pub fn tile(z: u32, x: u64, y: u64) -> MercatorBox {
        let size = 2.0 * HALF_WORLD_M / (1u64 << z.min(MAX_ZOOM)) as f64;
        let west = -HALF_WORLD_M + x as f64 * size;
        let north = HALF_WORLD_M - y as f64 * size;
        MercatorBox { west, south: north - size, east: west + size, north }
    }

    /// The box in longitude and latitude, degrees.
    pub fn geographic(&self) -> BBox {
        let lon = |x: f64| (x / MERCATOR_RADIUS_M).to_degrees();
        let lat = |y: f64| (y / MERCATOR_RADIUS_M).sinh().atan().to_degrees();
        BBox { west: lon(self.west), south: lat(self.south), east: lon(self.east), north: lat(self.north) }
    }
}

/// Web Mercator metres of a longitude/latitude (degrees).
pub fn to_mercator(lon_deg: f64, lat_deg: f64) -> (f64, f64) {
    let lat = lat_deg.clamp(-85.051_128_779_806_6, 85.051_128_779_806_6).to_radians();
    (MERCATOR_RADIUS_M * lon_deg.to_radians(), MERCATOR_RADIUS_M * lat.tan().asinh())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_boxes_nest_and_their_grids_hit_known_latitudes() {
        let world = MercatorBox::of_tile(0, 0, 0).unwrap();
        assert_eq!(
            world,
            MercatorBox { west: -HALF_WORLD_M, south: -HALF_WORLD_M, east: HALF_WORLD_M, north: HALF_WORLD_M }
        );
        let ne = MercatorBox::of_tile(1, 1, 0).unwrap();
        assert_eq!((ne.west, ne.south), (0.0, 0.0));
        // The centre of a 2×2 grid over the world sits at ±(half the square): latitude ±66.51°.
        let g = world.area_grid(2, 2).unwrap();
        assert!((g.lat.coord(0) - 66.513_260_443_111_83).abs() < 1e-9 && (g.lon.coord(1) - 90.0).abs() < 1e-12);
        assert!(MercatorBox::of_tile(3, 8, 0).is_err());
        let b = ne.geographic();
        assert_eq!((b.west, b.south), (0.0, 0.0));
        assert!((b.east - 180.0).abs() < 1e-9 && (b.north - 85.051_128_779_806_6).abs() < 1e-9, "{b:?}");
        let (x, y) = to_mercator(-105.7, 40.35);
        let back =
            MercatorBox { west: x - 1.0, south: y - 1.0, east: x + 1.0, north: y + 1.0 }.area_grid(1, 1).unwrap();
        assert!((back.lon.coord(0) + 105.7).abs() < 1e-9 && (back.lat.coord(0) - 40.35).abs() < 1e-9);
    }

    #[test]
    fn boxes_may_reach_past_the_square_but_not_span_two_worlds() {
        let h = HALF_WORLD_M;
        let past = MercatorBox { west: 0.9 * h, south: 1.2 * h, east: 1.1 * h, north: 1.4 * h }.checked().unwrap();
        let g = past.area_grid(2, 1).unwrap();
        assert!((g.lon.coord(1) - 189.0).abs() < 1e-9, "past the antimeridian: {}", g.lon.coord(1));
        assert!(g.lat.coord(0) > 85.06 && g.lat.coord(0) < 90.0, "past the square, short of the pole");
        let bad =
            |w: f64, s: f64, e: f64, n: f64| MercatorBox { west: w, south: s, east: e, north: n }.checked().is_err();
        assert!(bad(-h, 0.0, 1.1 * h, 1.0), "wider than the world");
        assert!(bad(0.0, 0.0, f64::NAN, 1.0) && bad(1.0, 0.0, 0.0, 1.0) && bad(0.0, 1.0, 1.0, 1.0));
        assert!(bad(3.1 * h, 0.0, 3.2 * h, 1.0) && bad(0.0, 0.0, 1.0, 3.1 * h), "beyond ±540°");
        assert!(!bad(2.9 * h, 2.9 * h, 3.0 * h, 3.0 * h));
    }
}
