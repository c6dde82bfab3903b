//! Small geographic helpers shared by the grid, the sources and the canopy proxy.

/// Mean Earth radius (IUGG), metres. Used only for ground distances and the
/// world-anchored metric frame of the canopy proxy, where a sphere is enough.
pub const EARTH_RADIUS_M: f64 = 6_371_008.8;

/// Metres per degree of a great circle on that sphere.
pub const METRES_PER_DEGREE: f64 = EARTH_RADIUS_M * std::f64::consts::PI / 180.0;

/// Brings a lattice coordinate onto the globe: latitudes past a pole are
/// reflected over it (moving to the opposite meridian), longitudes wrap into
/// `[-180, 180)`. Halos that reach across a pole or the antimeridian thus read
/// the data that is really there.
pub fn normalize(lon_deg: f64, lat_deg: f64) -> (f64, f64) {
    let (mut lon, mut lat) = (lon_deg, lat_deg);
    if lat > 90.0 {
        lat = 180.0 - lat;
        lon += 180.0;
    } else if lat < -90.0 {
        lat = -180.0 - lat;
        lon += 180.0;
    }
    (wrap_lon(lon), lat.clamp(-90.0, 90.0))
}

/// Wraps a longitude into `[-180, 180)`; values already inside are returned
/// bitwise unchanged.
pub fn wrap_lon(lon_deg: f64) -> f64 {
    if (-180.0..180.0).contains(&lon_deg) { lon_deg } else { (lon_deg + 180.0).rem_euclid(360.0) - 180.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poles_reflect_and_longitudes_wrap() {
        assert_eq!(normalize(10.0, 91.0), (-170.0, 89.0));
        assert_eq!(normalize(-170.0, -90.5), (10.0, -89.5));
        assert_eq!(normalize(181.0, 0.0), (-179.0, 0.0));
        assert_eq!(normalize(180.0, 0.0), (-180.0, 0.0));
        assert_eq!(normalize(12.345, 45.0), (12.345, 45.0));
    }
}
