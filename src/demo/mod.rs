//! The embedded demo region, Val Selva: a fictional alpine valley used when
//! no configuration is given, so that every command runs anywhere with no
//! data and every pipeline stage has something to do.
//!
//! It is built like a real data set, because the pipeline must treat it like
//! one: a 1″ DEM in EPSG:4326 ([`dem`], like SRTM-1 or Copernicus GLO-30) and
//! a 1:50,000 topographic sheet in UTM 32N at 10 m per pixel ([`map`]), so the
//! map needs reprojection and resampling onto the DEM's tiles. The sheet is
//! drawn like a Swiss 1:50,000 sheet ([`symbols`]): light-green forest
//! crossed by brown contours and black paths, so that finding the forest needs
//! the colour key with its tolerance and then the close of the dissertation's
//! section 6.3 (Figure 6.3: two 3 × 3 dilations, two erosions) to bridge the
//! lines, exactly as with a scanned map. Both are drawn from one continuous
//! terrain ([`terrain`], landforms in `shape`): a glacial valley with a lake
//! at 900 m, a river, side valleys, gullied flanks, a cliff band, and summits
//! near 2,900 m, so that forest, rock, water and open land all occur in
//! realistic shares.
//!
//! Invariant: everything here is a pure function of pixel indices: no I/O,
//! no state, no randomness beyond seeded hashes, so every block is the same
//! on every machine and in every order.

pub mod dem;
pub mod map;
mod relief;
mod shape;
pub mod symbols;
pub mod terrain;

#[cfg(test)]
mod preview;
#[cfg(test)]
mod sheet_tests;

use crate::source::{Georef, PixelSource, SourceError};
use std::sync::Arc;

/// The region's name.
pub const NAME: &str = "Sylva demo (Val Selva)";

/// The region's lat/lon box, W,S,E,N.
pub const BBOX: crate::grid::BBox = crate::grid::BBox { west: 10.0, south: 46.30, east: 10.25, north: 46.45 };

/// The sheet's colours (sRGB). Any two differ by at least 25 levels in
/// some channel, so a colour key with a tolerance of 10 (Lab ΔE) plus the
/// ±3 levels of scanner noise tells them apart.
pub mod palette {
    /// Forest fill (Swiss-map light green).
    pub const FOREST: [u8; 3] = [197, 227, 165];
    /// Open land (the paper).
    pub const OPEN: [u8; 3] = [250, 245, 218];
    /// Lake and river fill.
    pub const WATER: [u8; 3] = [160, 205, 240];
    /// Shore lines, river banks and streams.
    pub const SHORE: [u8; 3] = [46, 110, 180];
    /// Contour lines.
    pub const CONTOUR: [u8; 3] = [186, 130, 72];
    /// Roads and trails.
    pub const PATH: [u8; 3] = [35, 31, 32];
    /// Bare rock and scree (white, against the cream paper).
    pub const ROCK: [u8; 3] = [255, 255, 255];
    /// Scree dots and cliff hatching.
    pub const SCREE: [u8; 3] = [154, 154, 150];
    /// Kilometre grid.
    pub const GRID: [u8; 3] = [90, 110, 160];

    /// Every colour of the sheet, with its name.
    pub const ALL: [(&str, [u8; 3]); 9] = [
        ("forest", FOREST),
        ("open", OPEN),
        ("water", WATER),
        ("shore", SHORE),
        ("contour", CONTOUR),
        ("path", PATH),
        ("rock", ROCK),
        ("scree", SCREE),
        ("grid", GRID),
    ];
}

/// The demo's sources.
pub struct DemoSources {
    /// The 1″ DEM.
    pub dem: Arc<dyn PixelSource>,
    /// Where the DEM's pixels are.
    pub dem_georef: Georef,
    /// The topographic map (R, G, B, values 0–255).
    pub map: Arc<dyn PixelSource>,
    /// Where the map's pixels are.
    pub map_georef: Georef,
}

/// The demo DEM and map. Fails only if the UTM 32N definition cannot be set
/// up (a broken `proj4rs` build; a test shows it can).
pub fn sources() -> Result<DemoSources, SourceError> {
    let map = map::MapSource::new()?;
    let map_georef = map.georef();
    Ok(DemoSources { dem: Arc::new(dem::DemSource::new()?), dem_georef: dem::georef(), map: Arc::new(map), map_georef })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources_have_the_documented_sizes_and_georefs() {
        let s = sources().unwrap();
        assert_eq!((s.dem.size(), s.dem.bands(), s.dem.block_size()), ((936, 576), 1, (256, 256)));
        assert_eq!((s.map.size(), s.map.bands(), s.map.block_size()), ((2100, 1900), 3, (256, 256)));
        assert_eq!((s.dem_georef.crs.epsg(), s.map_georef.crs.epsg()), (4326, 32632));
        assert!((s.dem_georef.dx - 1.0 / 3600.0).abs() < 1e-15 && s.dem_georef.dy < 0.0);
        assert_eq!(
            (s.map_georef.x0, s.map_georef.y0, s.map_georef.dx, s.map_georef.dy),
            (576_005.0, 5_145_995.0, 10.0, -10.0)
        );
        assert_eq!((s.dem_georef.overhang, s.map_georef.overhang), (0.5, 0.5));
        assert!(BBOX.checked().is_ok());
    }

    #[test]
    fn palette_colours_are_distinct() {
        for (i, (a, ca)) in palette::ALL.iter().enumerate() {
            for (b, cb) in &palette::ALL[i + 1..] {
                let d = (0..3).map(|k| (i32::from(ca[k]) - i32::from(cb[k])).abs()).max().unwrap_or(0);
                assert!(d >= 25, "{a} and {b} differ by {d}");
            }
        }
    }
}
