//! `/xyz/{layer}/tiles.json`: a TileJSON 3.0 document for one layer's XYZ
//! tiles — the tile URL template, the zoom range and the region's bounds —
//! which a MapLibre `raster-dem` (heights, Terrarium) or `raster` (the
//! pictures) source reads from its `url`.

use super::products::XYZ_SIDE;
use super::routes::MAX_XYZ_ZOOM;
use super::wms::request::MapLayer;
use crate::grid::BBox;
use crate::region::Region;
use serde_json::{Value, json};

/// Web Mercator's equatorial circumference, metres.
const EQUATOR_M: f64 = 2.0 * std::f64::consts::PI * 6_378_137.0;

/// Web Mercator's latitude limit, degrees.
const MERCATOR_MAX_LAT: f64 = 85.051_128_779_806_6;

/// The TileJSON of `layer`'s XYZ tiles, served under `base`; none for a
/// region beyond Web Mercator's latitudes (around a pole), which has no
/// XYZ tiles.
pub fn document(region: &Region, layer: MapLayer, base: &str) -> Option<Value> {
    let Extent { bounds: b, min_zoom, max_zoom } = extent(region, layer)?;
    let mut doc = json!({
        "tilejson": "3.0.0",
        "name": format!("{} {}", region.name, layer.name()),
        "tiles": [format!("{base}/xyz/{}/{{z}}/{{x}}/{{y}}.png", layer.name())],
        "scheme": "xyz",
        "tileSize": TILE_PX,
        "minzoom": min_zoom,
        "maxzoom": max_zoom,
        "bounds": [b.west, b.south, b.east, b.north],
    });
    if !layer.is_picture() {
        doc["encoding"] = json!("terrarium");
    }
    Some(doc)
}

/// Where and at which zooms a layer's XYZ tiles hold the region.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extent {
    /// The region's box within ±180° of longitude (every longitude where it
    /// crosses the antimeridian: neither TileJSON's nor WMTS's boxes wrap)
    /// and Web Mercator's latitudes.
    pub bounds: BBox,
    /// The shallowest zoom at which the region spans a pixel (at most
    /// `max_zoom`).
    pub min_zoom: u32,
    /// The shallowest zoom as fine as the layer's finest source.
    pub max_zoom: u32,
}

/// The extent of `layer`'s XYZ tiles; none for a region beyond Web
/// Mercator's latitudes.
pub fn extent(region: &Region, layer: MapLayer) -> Option<Extent> {
    let b = region.bounds.on_the_globe();
    if b.south >= MERCATOR_MAX_LAT || b.north <= -MERCATOR_MAX_LAT {
        return None;
    }
    let lat = |l: f64| l.clamp(-MERCATOR_MAX_LAT, MERCATOR_MAX_LAT);
    let bounds = BBox { south: lat(b.south), north: lat(b.north), ..b };
    let max_zoom = max_zoom(region, layer);
    // A region smaller than a pixel of its finest source's zoom: that zoom alone.
    Some(Extent { bounds, min_zoom: min_zoom(region).min(max_zoom), max_zoom })
}

/// The side of an XYZ tile, pixels (MapLibre assumes 512 unless told).
const TILE_PX: u32 = XYZ_SIDE as u32;

/// The shallowest zoom at which the region spans a pixel (shallower tiles
/// hold no data: 404).
fn min_zoom(region: &Region) -> u32 {
    let b = region.bounds;
    let zoom = (360.0 / (f64::from(TILE_PX) * (b.east - b.west))).log2().ceil();
    if zoom.is_finite() { zoom.clamp(0.0, f64::from(MAX_XYZ_ZOOM)) as u32 } else { 0 }
}

/// The shallowest zoom whose pixels, at the region's middle latitude, are
/// no larger than the finest source of `layer` (the DEM's for `dem`, else
/// also the land cover's); clients draw deeper zooms from it.
fn max_zoom(region: &Region, layer: MapLayer) -> u32 {
    let cover = region.landcover.as_ref().filter(|_| layer != MapLayer::Data(crate::cem::Layer::Dem));
    let finest_m =
        std::iter::once(&region.dem).chain(cover).map(|r| r.georef().pixel_m()).fold(f64::INFINITY, f64::min);
    let b = region.bounds;
    let mid_lat = (0.5 * (b.south + b.north)).clamp(-MERCATOR_MAX_LAT, MERCATOR_MAX_LAT);
    let tile_px_m = EQUATOR_M * mid_lat.to_radians().cos() / f64::from(TILE_PX);
    let zoom = (tile_px_m / finest_m).log2().ceil();
    if zoom.is_finite() { zoom.clamp(0.0, f64::from(MAX_XYZ_ZOOM)) as u32 } else { MAX_XYZ_ZOOM }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_demo_dem_is_served_to_the_zoom_of_its_finest_pixels() {
        let region = crate::config::load(None).unwrap();
        let doc = document(&region, MapLayer::Data(crate::cem::Layer::Dem), "http://h:1").unwrap();
        assert_eq!(doc["tiles"][0], "http://h:1/xyz/dem/{z}/{x}/{y}.png");
        assert_eq!(doc["encoding"], "terrarium");
        assert_eq!(doc["tileSize"], 256);
        let zoom = doc["maxzoom"].as_u64().unwrap() as i32;
        // A pixel of that zoom is no larger than the DEM's, one of the zoom
        // before is.
        let finest = region.dem.georef().pixel_m();
        let px = |z: i32| EQUATOR_M * 46.375f64.to_radians().cos() / 256.0 / 2f64.powi(z);
        assert!(px(zoom) <= finest * 1.001 && px(zoom - 1) > finest, "zoom {zoom}: {} m, finest {finest} m", px(zoom));
        let relief = document(&region, MapLayer::Relief, "http://h:1").unwrap();
        assert!(relief.get("encoding").is_none());
        // The demo spans 0.25°: 1.4 px at zoom 3, 0.7 at zoom 2.
        assert_eq!(doc["minzoom"], 3);
    }

    #[test]
    fn a_region_beyond_web_mercator_has_no_xyz_tiles() {
        // Regression: it advertised bounds of zero height and zooms 0 to 4.
        let mut region = crate::config::load(None).unwrap();
        region.bounds = crate::grid::BBox { west: -180.0, south: -90.0, east: 180.0, north: -86.0 };
        assert!(document(&region, MapLayer::Relief, "http://h:1").is_none());
    }
}
