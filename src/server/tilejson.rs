//! `/xyz/{layer}/tiles.json`: a TileJSON 3.0 document for one layer's XYZ
//! tiles — the tile URL template, the zoom range and the region's bounds —
//! which a MapLibre `raster-dem` (heights, Terrarium) or `raster` (the
//! pictures) source reads from its `url`.

use super::extent::{Extent, extent};
use super::wms::request::MapLayer;
use crate::grid::quad::{SIDE, TileSet};
use crate::region::Region;
use serde_json::{Value, json};

/// The TileJSON of `layer`'s XYZ tiles, served under `base`; none for a
/// region beyond Web Mercator's latitudes (around a pole), which has no
/// XYZ tiles.
pub fn document(region: &Region, layer: MapLayer, base: &str) -> Option<Value> {
    let Extent { bounds: b, min_zoom, max_zoom } = extent(region, layer, TileSet::WebMercator)?;
    let mut doc = json!({
        "tilejson": "3.0.0",
        "name": format!("{} {}", region.name, layer.name()),
        "tiles": [format!("{base}/xyz/{}/{{z}}/{{x}}/{{y}}.png", layer.name())],
        "scheme": "xyz",
        // MapLibre assumes 512 unless told.
        "tileSize": SIDE,
        "minzoom": min_zoom,
        "maxzoom": max_zoom,
        "bounds": [b.west, b.south, b.east, b.north],
    });
    if !layer.is_picture() {
        doc["encoding"] = json!("terrarium");
    }
    Some(doc)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_demo_dem_is_served_at_the_zooms_of_its_web_mercator_extent() {
        let region = crate::config::load(None).unwrap();
        let dem = MapLayer::Data(crate::cem::Layer::Dem);
        let doc = document(&region, dem, "http://h:1").unwrap();
        assert_eq!(doc["tiles"][0], "http://h:1/xyz/dem/{z}/{x}/{y}.png");
        assert_eq!(doc["encoding"], "terrarium");
        assert_eq!(doc["tileSize"], 256);
        let e = extent(&region, dem, TileSet::WebMercator).unwrap();
        assert_eq!((doc["minzoom"].as_u64(), doc["maxzoom"].as_u64()), (Some(3), Some(u64::from(e.max_zoom))));
        let relief = document(&region, MapLayer::Relief, "http://h:1").unwrap();
        assert!(relief.get("encoding").is_none());
    }

    #[test]
    fn a_region_beyond_web_mercator_has_no_xyz_tiles() {
        // Regression: it advertised bounds of zero height and zooms 0 to 4.
        let mut region = crate::config::load(None).unwrap();
        region.bounds = crate::grid::BBox { west: -180.0, south: -90.0, east: 180.0, north: -86.0 };
        assert!(document(&region, MapLayer::Relief, "http://h:1").is_none());
    }
}
