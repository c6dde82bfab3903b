//! The WGS84 ellipsoid in `f64`: geodetic ↔ Earth-centred, Earth-fixed
//! (ECEF) coordinates, local east-north-up frames and the radii of
//! curvature. Tiles sit on this ellipsoid, as in NASA World Wind.
//!
//! Everything here is `f64`: an ECEF coordinate is ~6.4·10⁶ m, where an `f32`
//! step is half a metre. The GPU only ever sees differences of these values.

use glam::{DMat3, DVec3};

/// Semi-major axis, metres.
pub const A_M: f64 = 6_378_137.0;
/// Flattening.
pub const F: f64 = 1.0 / 298.257_223_563;
/// First eccentricity squared.
pub const E2: f64 = F * (2.0 - F);

/// A geodetic position: degrees and metres above the ellipsoid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geodetic {
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Latitude, degrees north.
    pub lat_deg: f64,
    /// Height above the ellipsoid, metres.
    pub height_m: f64,
}

impl Geodetic {
    /// A position from longitude, latitude and height.
    pub fn new(lon_deg: f64, lat_deg: f64, height_m: f64) -> Self {
        Geodetic { lon_deg, lat_deg, height_m }
    }

    /// The ECEF position.
    pub fn to_ecef(self) -> DVec3 {
        let (sin_lat, cos_lat) = self.lat_deg.to_radians().sin_cos();
        let (sin_lon, cos_lon) = self.lon_deg.to_radians().sin_cos();
        let n = prime_vertical_radius_m(sin_lat);
        let r = (n + self.height_m) * cos_lat;
        DVec3::new(r * cos_lon, r * sin_lon, (n * (1.0 - E2) + self.height_m) * sin_lat)
    }

    /// The geodetic position of an ECEF point (Bowring's method refined by
    /// four fixed-point steps: sub-millimetre from the centre to deep space).
    pub fn from_ecef(p: DVec3) -> Geodetic {
        let lon = p.y.atan2(p.x);
        let r = p.x.hypot(p.y);
        let b = A_M * (1.0 - F);
        let ep2 = E2 / (1.0 - E2);
        let theta = (p.z * A_M).atan2(r * b);
        let (st, ct) = theta.sin_cos();
        let mut lat = (p.z + ep2 * b * st.powi(3)).atan2(r - E2 * A_M * ct.powi(3));
        let mut height = 0.0;
        for _ in 0..4 {
            let (s, c) = lat.sin_cos();
            let n = prime_vertical_radius_m(s);
            height = if c.abs() > 1e-9 { r / c - n } else { p.z.abs() - n * (1.0 - E2) };
            lat = p.z.atan2(r * (1.0 - E2 * n / (n + height)));
        }
        Geodetic { lon_deg: lon.to_degrees(), lat_deg: lat.to_degrees(), height_m: height }
    }
}

/// Prime-vertical radius of curvature N at a latitude given by its sine.
pub fn prime_vertical_radius_m(sin_lat: f64) -> f64 {
    A_M / (1.0 - E2 * sin_lat * sin_lat).sqrt()
}

/// Meridional radius of curvature M at a latitude given by its sine.
pub fn meridional_radius_m(sin_lat: f64) -> f64 {
    A_M * (1.0 - E2) / (1.0 - E2 * sin_lat * sin_lat).powf(1.5)
}

/// The east-north-up basis at a geodetic position, as the columns of a
/// rotation from the local frame to ECEF.
pub fn enu_basis(lon_deg: f64, lat_deg: f64) -> DMat3 {
    let (sin_lat, cos_lat) = lat_deg.to_radians().sin_cos();
    let (sin_lon, cos_lon) = lon_deg.to_radians().sin_cos();
    let east = DVec3::new(-sin_lon, cos_lon, 0.0);
    let north = DVec3::new(-sin_lat * cos_lon, -sin_lat * sin_lon, cos_lat);
    let up = DVec3::new(cos_lat * cos_lon, cos_lat * sin_lon, sin_lat);
    DMat3::from_cols(east, north, up)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn known_points() {
        let p = Geodetic::new(0.0, 0.0, 0.0).to_ecef();
        assert!((p - DVec3::new(A_M, 0.0, 0.0)).length() < 1e-6);
        let pole = Geodetic::new(0.0, 90.0, 0.0).to_ecef();
        assert!((pole.z - A_M * (1.0 - F)).abs() < 1e-6);
    }

    #[test]
    fn enu_is_orthonormal_and_up_is_the_normal() {
        let m = enu_basis(10.2, 46.4);
        assert!((m.transpose() * m - DMat3::IDENTITY).to_cols_array().iter().all(|v| v.abs() < 1e-12));
        let a = Geodetic::new(10.2, 46.4, 0.0).to_ecef();
        let b = Geodetic::new(10.2, 46.4, 1000.0).to_ecef();
        assert!(((b - a).normalize() - m.z_axis).length() < 1e-12);
    }

    proptest! {
        #[test]
        fn ecef_round_trips(lon in -180.0f64..180.0, lat in -90.0f64..=90.0, h in -11_000.0f64..1.0e7) {
            let g = Geodetic::from_ecef(Geodetic::new(lon, lat, h).to_ecef());
            prop_assert!((g.height_m - h).abs() < 1e-4, "height {} vs {}", g.height_m, h);
            prop_assert!((g.lat_deg - lat).abs() < 1e-9);
            if lat.abs() < 89.9999 {
                let dlon = (g.lon_deg - lon + 540.0).rem_euclid(360.0) - 180.0;
                prop_assert!(dlon.abs() < 1e-9);
            }
        }
    }
}
