//! Vertical CRSs of the EPSG registry whose values are not heights in
//! metres: a GeoTIFF's VerticalCSTypeGeoKey names one, and GDAL writes no
//! unit key beside it, so a DEM in NAVD88 feet (`EPSG:6360`) must be known
//! by its code. The list is every such CRS of PROJ's database (proj.db,
//! `vertical_crs` whose axis is not metres up), examples left out.

/// The international foot, metres.
const FOOT: f64 = 0.3048;
/// The US survey foot, metres.
const US_FOOT: f64 = 1200.0 / 3937.0;
/// The British foot (1936), metres.
const BRITISH_FOOT_1936: f64 = 0.3048007491;

/// EPSG code, then metres up per stored unit (negative for depths).
const NOT_METRES_UP: [(u16, f64); 36] = [
    (5336, -1.0),              // Black Sea depth
    (5612, -1.0),              // Baltic 1977 depth
    (5614, -FOOT),             // KOC WD depth (ft)
    (5702, US_FOOT),           // NGVD29 height (ftUS)
    (5706, -1.0),              // Caspian depth
    (5715, -1.0),              // MSL depth
    (5734, -1.0),              // AIOC95 depth
    (5739, -1.0),              // HKCD depth
    (5754, BRITISH_FOOT_1936), // Poolbeg height (ft(Br36))
    (5789, -1.0),              // KOC WD depth
    (5831, -1.0),              // Instantaneous Water Level depth
    (5861, -1.0),              // LAT depth
    (5862, -1.0),              // LLWLT depth
    (5863, -1.0),              // ISLW depth
    (5864, -1.0),              // MLLWS depth
    (5865, -1.0),              // MLWS depth
    (5866, -1.0),              // MLLW depth
    (5867, -1.0),              // MLW depth
    (5873, -1.0),              // Low Water depth
    (6130, FOOT),              // GCVD54 height (ft)
    (6131, FOOT),              // LCVD61 height (ft)
    (6132, FOOT),              // CBVD61 height (ft)
    (6357, -1.0),              // NAVD88 depth
    (6358, -US_FOOT),          // NAVD88 depth (ftUS)
    (6359, -US_FOOT),          // NGVD29 depth (ftUS)
    (6360, US_FOOT),           // NAVD88 height (ftUS)
    (7976, -1.0),              // HKPD depth
    (8050, FOOT),              // MSL height (ft)
    (8051, -FOOT),             // MSL depth (ft)
    (8052, US_FOOT),           // MSL height (ftUS)
    (8053, -US_FOOT),          // MSL depth (ftUS)
    (8228, FOOT),              // NAVD88 height (ft)
    (8358, -1.0),              // Baltic 1957 depth
    (9287, -1.0),              // LAT NL depth
    (9288, -1.0),              // MSL NL depth
    (9672, -1.0),              // CD Norway depth
];

/// Metres up per stored unit of the vertical CRS `EPSG:code`: `None` for
/// one in metres up, or one not in the registry.
pub fn metres_up(code: u16) -> Option<f64> {
    NOT_METRES_UP.iter().find(|&&(c, _)| c == code).map(|&(_, m)| m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feet_and_depths_are_known_by_their_codes() {
        assert_eq!(metres_up(6360), Some(US_FOOT), "NAVD88 height (ftUS)");
        assert_eq!(metres_up(8228), Some(FOOT), "NAVD88 height (ft)");
        assert_eq!(metres_up(5715), Some(-1.0), "MSL depth");
        assert_eq!(metres_up(5703), None, "NAVD88 height, metres");
        assert!(NOT_METRES_UP.windows(2).all(|w| w[0].0 < w[1].0), "sorted, each once");
    }
}
