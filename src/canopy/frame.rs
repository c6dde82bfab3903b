//! The world-anchored metric frame of texture proxies: where on the globe a
//! canopy texture's texels lie.
//!
//! A texture needs square metres, the globe has none that tile it. The frame
//! cuts the globe into zones of [`ZONE_DEG`] of longitude; in zone `z` with
//! central meridian `λz` a point is at `x = R·cos φ·(λ − λz)`,
//! `y = R·φ` (the sinusoidal projection about `λz`): true distances along
//! parallels and meridians, and a shear below `sin φ · 1.5°` (2.6 %), invisible
//! in a canopy. Rows of texture tiles line up across the whole zone. Within
//! [`Zone::blend_m`] of a zone edge the two zones' canopies are blended, so the
//! canopy is continuous across the edge (it looks mixed in a strip every
//! 3° of longitude, 250 km at 45°).
//!
//! Invariant: a pure function of the point's longitude and latitude, so
//! every grid that holds a sample gives it the same position.

use super::blend::smoothstep;
use crate::geo::EARTH_RADIUS_M;

/// Width of a zone, degrees.
pub const ZONE_DEG: f64 = 3.0;

/// Zones around the globe.
pub const ZONES: i64 = (360.0 / ZONE_DEG) as i64;

/// A point in one zone's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Position {
    /// The zone, `0 .. ZONES` from −180°.
    pub zone: i64,
    /// East of the central meridian along the parallel, metres.
    pub x_m: f64,
    /// North of the equator, metres.
    pub y_m: f64,
}

/// The frame with its blend width.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Zone {
    /// Half-width of the blend across a zone edge, metres.
    pub blend_m: f64,
}

impl Zone {
    /// The point `(lon, lat)` (degrees, normalised) in its own zone and, near
    /// a zone edge, in the neighbouring zone, with the weights of both.
    pub fn locate(&self, lon_deg: f64, lat_deg: f64) -> [(f32, Position); 2] {
        let zone = (((lon_deg + 180.0) / ZONE_DEG).floor() as i64).clamp(0, ZONES - 1);
        let west = -180.0 + zone as f64 * ZONE_DEG;
        let m_per_deg = EARTH_RADIUS_M * lat_deg.to_radians().cos() * std::f64::consts::PI / 180.0;
        let (to_west, to_east) = ((lon_deg - west) * m_per_deg, (west + ZONE_DEG - lon_deg) * m_per_deg);
        let (inside, neighbour) =
            if to_west < to_east { (to_west, (zone + ZONES - 1) % ZONES) } else { (to_east, (zone + 1) % ZONES) };
        // ½ on the edge, rising to 1 at blend_m inside; the neighbour's weight mirrors it.
        let own = (0.5 + 0.5 * smoothstep(inside / self.blend_m)) as f32;
        [(own, position(zone, lon_deg, lat_deg)), (1.0 - own, position(neighbour, lon_deg, lat_deg))]
    }
}

/// `(lon, lat)` in zone `zone`'s frame.
pub fn position(zone: i64, lon_deg: f64, lat_deg: f64) -> Position {
    let central = -180.0 + (zone as f64 + 0.5) * ZONE_DEG;
    let d_lon = crate::geo::wrap_lon(lon_deg - central);
    let phi = lat_deg.to_radians();
    Position { zone, x_m: EARTH_RADIUS_M * phi.cos() * d_lon.to_radians(), y_m: EARTH_RADIUS_M * phi }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_are_true_and_zone_edges_split_the_weight() {
        let z = Zone { blend_m: 128.0 };
        let [(w, p), (v, _)] = z.locate(10.7, 46.0);
        assert_eq!((w, v, p.zone), (1.0, 0.0, 63));
        // 100 m east along the parallel is 100 m in x.
        let dx = 100.0 / (EARTH_RADIUS_M * 46f64.to_radians().cos()) * 180.0 / std::f64::consts::PI;
        assert!((position(63, 10.7 + dx, 46.0).x_m - p.x_m - 100.0).abs() < 1e-6);
        let [(w, a), (v, b)] = z.locate(12.0, 46.0);
        assert_eq!((w, v, a.zone, b.zone), (0.5, 0.5, 64, 63));
        // The antimeridian: the zones on both sides are neighbours.
        let [(_, a), (_, b)] = z.locate(-180.0, 10.0);
        assert_eq!((a.zone, b.zone), (0, ZONES - 1));
    }
}
