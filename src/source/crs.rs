//! Coordinate reference systems of sources, by EPSG code, through `proj4rs`
//! (a pure-Rust port of PROJ; matches PROJ to < 0.01 mm except datum shifts).
//!
//! Sylva's tiles are in geographic WGS84 coordinates. Geographic sources are
//! read in degrees directly; projected ones (UTM, NZTM, BC Albers, …) go through
//! the projection. Datum shifts between WGS84 and NAD83 / NZGD2000 are below a
//! metre and are not applied (their proj strings use a zero `towgs84`).

use proj4rs::Proj;
use std::fmt;
use thiserror::Error;

/// A CRS that cannot be used.
#[derive(Debug, Error)]
pub enum CrsError {
    /// The EPSG code is not in the definitions table.
    #[error("EPSG:{0} is not a known coordinate reference system")]
    Unknown(u32),
    /// The definition exists but the projection cannot be set up.
    #[error("EPSG:{code} cannot be used: {reason}")]
    Unusable {
        /// EPSG code.
        code: u32,
        /// What proj4rs said.
        reason: String,
    },
}

/// `"EPSG:26910"` (or `epsg:26910`) → 26910.
pub fn parse_epsg(text: &str) -> Result<u32, String> {
    let t = text.trim();
    let code = t.strip_prefix("EPSG:").or_else(|| t.strip_prefix("epsg:"));
    code.and_then(|c| c.parse().ok()).ok_or_else(|| format!("crs {t:?} is not of the form \"EPSG:code\""))
}

/// A source CRS: geographic (degrees) or projected (metres).
pub struct Crs {
    epsg: u32,
    kind: Kind,
}

enum Kind {
    Geographic,
    Projected { proj: Box<Proj>, wgs84: Box<Proj> },
}

impl fmt::Debug for Crs {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "EPSG:{}", self.epsg)
    }
}

impl Crs {
    /// WGS84 geographic, EPSG:4326.
    pub fn wgs84() -> Crs {
        Crs { epsg: 4326, kind: Kind::Geographic }
    }

    /// The CRS with this EPSG code.
    pub fn from_epsg(code: u32) -> Result<Crs, CrsError> {
        let short = u16::try_from(code).map_err(|_| CrsError::Unknown(code))?;
        let proj = Proj::from_epsg_code(short).map_err(|e| match e {
            proj4rs::errors::Error::ProjectionNotFound => CrsError::Unknown(code),
            other => CrsError::Unusable { code, reason: other.to_string() },
        })?;
        if proj.is_latlong() {
            return Ok(Crs { epsg: code, kind: Kind::Geographic });
        }
        if proj.is_geocent() {
            return Err(CrsError::Unusable {
                code,
                reason: "geocentric (x, y, z from the Earth's centre), not a map".into(),
            });
        }
        let wgs84 = Proj::from_epsg_code(4326).map_err(|e| CrsError::Unusable { code, reason: e.to_string() })?;
        Ok(Crs { epsg: code, kind: Kind::Projected { proj: Box::new(proj), wgs84: Box::new(wgs84) } })
    }

    /// The EPSG code.
    pub fn epsg(&self) -> u32 {
        self.epsg
    }

    /// True for latitude/longitude systems.
    pub fn is_geographic(&self) -> bool {
        matches!(self.kind, Kind::Geographic)
    }

    /// Metres per horizontal unit of a projected CRS (1 for metres, 0.3048
    /// for feet); `None` for a geographic one.
    pub fn metres_per_unit(&self) -> Option<f64> {
        match &self.kind {
            Kind::Geographic => None,
            Kind::Projected { proj, .. } => Some(proj.to_meter()),
        }
    }

    /// How far x goes once around the globe, in the CRS's units, where x
    /// follows longitude alone, evenly (360 for geographic CRSs; the
    /// equator's length for Web Mercator and other cylindrical projections
    /// centred on the prime meridian); `None` for other projections.
    pub fn period_x(&self) -> Option<f64> {
        if self.is_geographic() {
            return Some(360.0);
        }
        let x = |lon: f64, lat: f64| self.from_lon_lat(lon, lat).map(|p| p.0);
        let quarter = x(90.0, 0.0)? - x(0.0, 0.0)?;
        let steps = [x(0.0, 0.0)? - x(-90.0, 0.0)?, x(90.0, 60.0)? - x(0.0, 60.0)?];
        let even = quarter > 0.0 && steps.iter().all(|s| (s - quarter).abs() <= 1e-9 * quarter);
        even.then_some(4.0 * quarter)
    }

    /// Projects `(lon, lat)` degrees into this CRS; `None` where the projection
    /// is undefined.
    pub fn from_lon_lat(&self, lon_deg: f64, lat_deg: f64) -> Option<(f64, f64)> {
        match &self.kind {
            Kind::Geographic => Some((lon_deg, lat_deg)),
            Kind::Projected { proj, wgs84 } => {
                let mut p = (lon_deg.to_radians(), lat_deg.to_radians(), 0.0);
                proj4rs::transform::transform(wgs84, proj, &mut p).ok()?;
                (p.0.is_finite() && p.1.is_finite()).then_some((p.0, p.1))
            }
        }
    }

    /// Converts a position in this CRS to `(lon, lat)` degrees.
    pub fn to_lon_lat(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        match &self.kind {
            Kind::Geographic => Some((x, y)),
            Kind::Projected { proj, wgs84 } => {
                let mut p = (x, y, 0.0);
                proj4rs::transform::transform(proj, wgs84, &mut p).ok()?;
                (p.0.is_finite() && p.1.is_finite()).then_some((p.0.to_degrees(), p.1.to_degrees()))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utm_round_trips_and_matches_a_known_point() {
        // Mt Hood summit (45.3736 N, 121.6960 W) in UTM 10N, as GDAL 3.6 gdaltransform gives it.
        let utm = Crs::from_epsg(26910).unwrap();
        let (x, y) = utm.from_lon_lat(-121.6960, 45.3736).unwrap();
        assert!((x - 602_104.950_6).abs() < 1e-3 && (y - 5_025_280.992_1).abs() < 1e-3, "{x} {y}");
        let (lon, lat) = utm.to_lon_lat(x, y).unwrap();
        assert!((lon + 121.6960).abs() < 1e-9 && (lat - 45.3736).abs() < 1e-9);
    }

    #[test]
    fn unknown_codes_are_named() {
        let err = Crs::from_epsg(99999).unwrap_err();
        assert!(err.to_string().contains("EPSG:99999"));
        assert!(Crs::from_epsg(4269).unwrap().is_geographic());
        assert!(!Crs::from_epsg(2193).unwrap().is_geographic());
        // Regression: EPSG:4978 was taken for a map, its x and y for eastings
        // and northings (bounds near 86° E, 0° N).
        let err = Crs::from_epsg(4978).unwrap_err().to_string();
        assert!(err.contains("EPSG:4978 cannot be used: geocentric"), "{err}");
    }

    #[test]
    fn x_goes_around_the_globe_in_geographic_and_cylindrical_crss_only() {
        let period = |code| Crs::from_epsg(code).unwrap().period_x();
        assert_eq!(period(4326), Some(360.0));
        let mercator = period(3857).unwrap();
        assert!((mercator - 2.0 * crate::grid::mercator::HALF_WORLD_M).abs() < 1e-6, "{mercator}");
        assert_eq!((period(32610), period(3031), period(2193)), (None, None, None));
    }
}
