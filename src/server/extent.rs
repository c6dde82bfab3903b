//! Where and at which zooms a layer's tiles in a quadtree set hold the
//! region: the box and zooms TileJSON advertises; the box whose tiles are
//! a WMTS layer's limits in every matrix, and the zoom that ends a matrix
//! set (the deepest of its layers').

use super::routes::MAX_XYZ_ZOOM;
use super::wms::request::MapLayer;
use crate::grid::BBox;
use crate::grid::quad::TileSet;
use crate::region::Region;

/// Web Mercator's latitude limit, degrees.
const MERCATOR_MAX_LAT: f64 = 85.051_128_779_806_6;

/// Where and at which zooms a layer's tiles hold the region.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extent {
    /// The region's box within ±180° of longitude (every longitude where it
    /// crosses the antimeridian: neither TileJSON's nor WMTS's boxes wrap)
    /// and the set's latitudes.
    pub bounds: BBox,
    /// The shallowest zoom at which the region spans a pixel (at most
    /// `max_zoom`).
    pub min_zoom: u32,
    /// The shallowest zoom as fine as the layer's finest source.
    pub max_zoom: u32,
}

impl Extent {
    /// Whether tile `(z, col, row)` of `set` lies over the bounds (within
    /// WMTS's limits of its matrix).
    pub fn holds(&self, set: TileSet, (z, col, row): (u32, u64, u64)) -> bool {
        let ((c0, r0), (c1, r1)) = set.tiles_over(&self.bounds, z);
        (c0..=c1).contains(&col) && (r0..=r1).contains(&row)
    }
}

/// The extent of `layer`'s tiles in `set`; none for a region beyond Web
/// Mercator's latitudes (around a pole) in that set.
pub fn extent(region: &Region, layer: MapLayer, set: TileSet) -> Option<Extent> {
    let b = region.bounds.on_the_globe();
    let bounds = match set {
        TileSet::Crs84 => b,
        TileSet::WebMercator if b.south >= MERCATOR_MAX_LAT || b.north <= -MERCATOR_MAX_LAT => return None,
        TileSet::WebMercator => {
            let lat = |l: f64| l.clamp(-MERCATOR_MAX_LAT, MERCATOR_MAX_LAT);
            BBox { south: lat(b.south), north: lat(b.north), ..b }
        }
    };
    let max_zoom = max_zoom(region, layer, set);
    // A region smaller than a pixel of its finest source's zoom: that zoom alone.
    Some(Extent { bounds, min_zoom: min_zoom(region, set).min(max_zoom), max_zoom })
}

/// The shallowest zoom at which the region spans a pixel (shallower tiles
/// hold no data: 404).
fn min_zoom(region: &Region, set: TileSet) -> u32 {
    let b = region.bounds;
    let zoom = (set.pixel_deg() / (b.east - b.west)).log2().ceil();
    if zoom.is_finite() { zoom.clamp(0.0, f64::from(MAX_XYZ_ZOOM)) as u32 } else { 0 }
}

/// The shallowest zoom whose pixels, at the region's middle latitude, are
/// no larger than the finest source of `layer`.
fn max_zoom(region: &Region, layer: MapLayer, set: TileSet) -> u32 {
    let b = region.bounds;
    let mid_lat = (0.5 * (b.south + b.north)).clamp(-MERCATOR_MAX_LAT, MERCATOR_MAX_LAT);
    finest_zoom(region, layer, set.pixel_m(mid_lat))
}

/// The shallowest zoom of a quadtree whose samples are `zoom0_m` apart at
/// zoom 0 where they are no farther apart than the finest source of
/// `layer` (the DEM's for `dem`, else also the land cover's); clients draw
/// deeper zooms from it.
pub fn finest_zoom(region: &Region, layer: MapLayer, zoom0_m: f64) -> u32 {
    let cover = region.landcover.as_ref().filter(|_| layer != MapLayer::Data(crate::cem::Layer::Dem));
    let finest_m =
        std::iter::once(&region.dem).chain(cover).map(|r| r.georef().pixel_m()).fold(f64::INFINITY, f64::min);
    let zoom = (zoom0_m / finest_m).log2().ceil();
    if zoom.is_finite() { zoom.clamp(0.0, f64::from(MAX_XYZ_ZOOM)) as u32 } else { MAX_XYZ_ZOOM }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cem::Layer;

    #[test]
    fn each_set_is_served_to_the_zoom_of_the_finest_pixels() {
        let region = crate::config::load(None).unwrap();
        let finest = region.dem.georef().pixel_m();
        for set in TileSet::ALL {
            let e = extent(&region, MapLayer::Data(Layer::Dem), set).unwrap();
            // A pixel of that zoom is no larger than the DEM's, one of the
            // zoom before is.
            let zoom0_m = match set {
                TileSet::WebMercator => 156_543.034 * 46.375f64.to_radians().cos(),
                TileSet::Crs84 => 78_271.517,
            };
            let px = |z: u32| zoom0_m / 2f64.powi(z as i32);
            let z = e.max_zoom;
            assert!(
                z > 0 && px(z) <= finest * 1.001 && px(z - 1) > finest,
                "{set:?} zoom {z}: {} m, {finest} m",
                px(z)
            );
            assert_eq!(e.bounds, region.bounds);
        }
        // The demo spans 0.25°: 1.4 pixels of Web Mercator's zoom 3, 0.7 of
        // zoom 2; geographic pixels are half as wide.
        let min = |set| extent(&region, MapLayer::Relief, set).unwrap().min_zoom;
        assert_eq!((min(TileSet::WebMercator), min(TileSet::Crs84)), (3, 2));
    }

    #[test]
    fn a_polar_region_has_geographic_tiles_only() {
        // Regression: it advertised XYZ bounds of zero height and zooms 0 to 4.
        let mut region = crate::config::load(None).unwrap();
        region.bounds = BBox { west: -180.0, south: -90.0, east: 180.0, north: -86.0 };
        assert!(extent(&region, MapLayer::Relief, TileSet::WebMercator).is_none());
        let polar = extent(&region, MapLayer::Relief, TileSet::Crs84).unwrap();
        assert_eq!((polar.bounds, polar.min_zoom), (region.bounds, 0));
    }
}
