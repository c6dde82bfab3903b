//! `/xyz/{layer}/tiles.json`: a TileJSON 3.0 document for one layer's XYZ
//! tiles — the tile URL template, the zoom range and the region's bounds —
//! which a MapLibre `raster-dem` (heights, Terrarium) or `raster` (the
//! pictures) source reads from its `url`.

use super::routes::MAX_XYZ_ZOOM;
use super::wms::request::MapLayer;
use crate::region::Region;
use serde_json::{Value, json};

/// Web Mercator's equatorial circumference, metres.
const EQUATOR_M: f64 = 2.0 * std::f64::consts::PI * 6_378_137.0;

/// Web Mercator's latitude limit, degrees.
const MERCATOR_MAX_LAT: f64 = 85.051_128_779_806_6;

/// The TileJSON of `layer`'s XYZ tiles, served under `base`.
pub fn document(region: &Region, layer: MapLayer, base: &str) -> Value {
    let b = region.bounds;
    let lat = |l: f64| l.clamp(-MERCATOR_MAX_LAT, MERCATOR_MAX_LAT);
    let mut doc = json!({
        "tilejson": "3.0.0",
        "name": format!("{} {}", region.name, layer.name()),
        "tiles": [format!("{base}/xyz/{}/{{z}}/{{x}}/{{y}}.png", layer.name())],
        "scheme": "xyz",
        "minzoom": 0,
        "maxzoom": max_zoom(region),
        "bounds": [b.west, lat(b.south), b.east, lat(b.north)],
    });
    if !layer.is_picture() {
        doc["encoding"] = json!("terrarium");
    }
    doc
}

/// The shallowest zoom whose pixels, at the region's middle latitude, are
/// no larger than its finest source's (clients draw deeper zooms from it).
fn max_zoom(region: &Region) -> u32 {
    let finest_m = std::iter::once(&region.dem)
        .chain(region.landcover.as_ref())
        .map(|r| r.georef().pixel_m())
        .fold(f64::INFINITY, f64::min);
    let b = region.bounds;
    let mid_lat = (0.5 * (b.south + b.north)).clamp(-MERCATOR_MAX_LAT, MERCATOR_MAX_LAT);
    let tile_px_m = EQUATOR_M * mid_lat.to_radians().cos() / 256.0;
    let zoom = (tile_px_m / finest_m).log2().ceil();
    if zoom.is_finite() { zoom.clamp(0.0, f64::from(MAX_XYZ_ZOOM)) as u32 } else { MAX_XYZ_ZOOM }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_demo_dem_is_served_to_the_zoom_of_its_finest_pixels() {
        let region = crate::config::load(None).unwrap();
        let doc = document(&region, MapLayer::Data(crate::cem::Layer::Dem), "http://h:1");
        assert_eq!(doc["tiles"][0], "http://h:1/xyz/dem/{z}/{x}/{y}.png");
        assert_eq!(doc["encoding"], "terrarium");
        let zoom = doc["maxzoom"].as_u64().unwrap() as i32;
        // A pixel of that zoom is no larger than the finest source pixel,
        // one of the zoom before is.
        let finest =
            region.dem.georef().pixel_m().min(region.landcover.as_ref().map_or(f64::MAX, |l| l.georef().pixel_m()));
        let px = |z: i32| EQUATOR_M * 46.375f64.to_radians().cos() / 256.0 / 2f64.powi(z);
        assert!(px(zoom) <= finest * 1.001 && px(zoom - 1) > finest, "zoom {zoom}: {} m, finest {finest} m", px(zoom));
        let relief = document(&region, MapLayer::Relief, "http://h:1");
        assert!(relief.get("encoding").is_none());
    }
}
