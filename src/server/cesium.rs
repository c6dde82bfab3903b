//! `/cesium/{layer}`: heights as Cesium terrain, for CesiumJS's
//! `CesiumTerrainProvider` (`url` = the layer's directory): `layer.json`
//! says the format (`heightmap-1.0`), the tiling (the geographic quadtree of
//! two 180° tiles at zoom 0, rows counted from the south: TMS) and which
//! tiles exist; `{z}/{x}/{y}.terrain` is a tile of 65 × 65 point-registered
//! samples (neighbours share their edges, as Cesium stitches them) of `dem`
//! or `cem` (the ground raised by the canopy) with a water mask from the
//! surface classes (Cesium animates water there), encoded by
//! [`crate::encode::heightmap`].
//!
//! Which tiles exist: both of zoom 0 (Cesium starts from them, over the
//! whole globe), and at zooms 1 to the one as fine as the layer's finest
//! source the tiles over the region; Cesium draws deeper views from the
//! deepest, and the globe beyond the region from zoom 0's (0 m where there
//! is no data). Others are 404.

use super::extent::finest_zoom;
use super::products::{Computed, Encoding, Product};
use super::routes::{level_number, meta, whole_number};
use super::wms::request::MapLayer;
use super::{AppState, ServeError};
use crate::cem::surface::SurfaceType;
use crate::cem::{self, Layer, LayerSamples, Stats};
use crate::encode::heightmap::Children;
use crate::encode::{self, EncodeError};
use crate::grid::quad::{SIDE, TileSet, geographic_box};
use crate::grid::{BBox, GridError, SampleGrid};
use crate::produce::ProduceError;
use crate::raster::Raster;
use crate::region::Region;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, header};
use axum::response::{IntoResponse, Response};
use serde_json::{Value, json};
use std::sync::Arc;
use std::time::Instant;

/// Samples per tile side.
const SAMPLES: usize = 65;

/// The layers served as terrain.
pub const LAYERS: [Layer; 2] = [Layer::Dem, Layer::Cem];

/// Computes tile `zxy` of `layer` on its samples, `grid` ([`tile_grid`]):
/// its heights (NaN, encoded 0 m, off the region's data), which children
/// exist, and where water is.
pub fn compute(
    region: &Region,
    layer: Layer,
    zxy: (u32, u64, u64),
    grid: &SampleGrid,
) -> Result<Computed, ProduceError> {
    let (heights, surface, mut stats) = if region.dem.may_cover(grid) {
        let mut products = cem::compute(region, grid, &[layer, Layer::Surface])?;
        let heights = match products.take(layer) {
            Some(LayerSamples::Float(heights)) => heights,
            _ => return Err(EncodeError(format!("layer {} holds no heights", layer.name())).into()),
        };
        (heights, products.surface, products.stats)
    } else {
        (Raster::filled(grid.width(), grid.height(), f32::NAN), None, Stats::default())
    };
    let water = water_mask(region, zxy, surface.as_ref(), &mut stats)?;
    let start = Instant::now();
    let bytes = encode::heightmap::encode(&heights, children(region, layer, zxy), &water);
    Ok(Computed { bytes, uniform: false, stats, encode: start.elapsed() })
}

/// Side of a water mask that tells water from land within a tile, texels
/// (Cesium's, over the tile's area, row 0 north).
const MASK_SIDE: usize = 256;

/// The water mask of tile `zxy` whose samples have `surface` classes: one
/// byte when they agree (0: no water, 255: all water), else the surface's
/// water class at the centres of a 256² grid over the tile (computed then,
/// its stages added to `stats`).
fn water_mask(
    region: &Region,
    zxy: (u32, u64, u64),
    surface: Option<&Raster<u8>>,
    stats: &mut Stats,
) -> Result<Vec<u8>, ProduceError> {
    let water = |&class: &u8| class == SurfaceType::Water as u8;
    let Some(classes) = surface.map(Raster::data).filter(|c| c.iter().any(water)) else {
        return Ok(vec![0]);
    };
    if classes.iter().all(water) {
        return Ok(vec![255]);
    }
    let grid = tile_box(zxy).area_grid(MASK_SIDE, MASK_SIDE)?;
    let products = cem::compute(region, &grid, &[Layer::Surface])?;
    *stats += products.stats;
    let classes = products.surface.ok_or_else(|| EncodeError("the surface was not computed".into()))?;
    Ok(classes.data().iter().map(|c| if water(c) { 255 } else { 0 }).collect())
}

/// `/cesium/{layer}/layer.json`.
pub async fn layer_json(State(state): State<Arc<AppState>>, Path(layer): Path<String>) -> Result<Response, ServeError> {
    let doc = document(state.region(), terrain_layer(&layer)?);
    Ok(([(header::CONTENT_TYPE, "application/json")], doc.to_string()).into_response())
}

/// `/cesium/{layer}/{z}/{x}/{y}.terrain`.
pub async fn tile(
    State(state): State<Arc<AppState>>,
    Path((layer, z, x, file)): Path<(String, String, String, String)>,
    headers: HeaderMap,
) -> Result<Response, ServeError> {
    let layer = terrain_layer(&layer)?;
    let y = file
        .strip_suffix(".terrain")
        .ok_or_else(|| ServeError::BadRequest(format!("terrain tiles are {{y}}.terrain, not {file:?}")))?;
    let zxy = (level_number(&z, "zoom")?, whole_number(&x, "x")?, whole_number(y, "y")?);
    if !exists(state.region(), layer, zxy) {
        return Err(ServeError::NotFound);
    }
    let t = state.tiles.get(Product::Terrain { layer, zxy }).await?;
    Ok(super::respond::tile(&t, &meta(&state, MapLayer::Data(layer), Encoding::Heightmap), &headers))
}

/// A layer served as terrain.
fn terrain_layer(name: &str) -> Result<Layer, ServeError> {
    LAYERS.into_iter().find(|l| l.name() == name).ok_or_else(|| {
        let names: Vec<&str> = LAYERS.iter().map(|l| l.name()).collect();
        ServeError::BadRequest(format!("no terrain layer {name:?}: {}", names.join(", ")))
    })
}

/// The samples of tile `(z, x, y)` (y from the south), or an error if it
/// does not exist in the quadtree.
pub fn tile_grid(region: &Region, (z, x, y): (u32, u64, u64)) -> Result<SampleGrid, GridError> {
    TileSet::Crs84.check(z, x, y)?;
    tile_box((z, x, y)).point_grid(SAMPLES, SAMPLES, &region.tiles)
}

/// The box of existing tile `(z, x, y)`: the geographic set's tile whose
/// row counted from the north is `y`'s from the south.
pub fn tile_box((z, x, y): (u32, u64, u64)) -> BBox {
    geographic_box(z, x, TileSet::Crs84.matrix(z).1 - 1 - y)
}

/// The deepest zoom of `layer`: the first whose samples are as close as its
/// finest source's.
pub fn deepest(region: &Region, layer: Layer) -> u32 {
    // 64 sample intervals across a zoom-0 tile's 180°, at the equator.
    let zoom0_m = TileSet::Crs84.pixel_m(0.0) * SIDE as f64 / (SAMPLES - 1) as f64;
    finest_zoom(region, MapLayer::Data(layer), zoom0_m)
}

/// The tiles of zoom `z` that exist, as ranges of (x, y) from the first
/// to the last: both at zoom 0, those over the region to the deepest zoom
/// (a range on each side of the antimeridian where the region crosses it),
/// none deeper.
fn available(region: &Region, layer: Layer, z: u32) -> Vec<((u64, u64), (u64, u64))> {
    if z == 0 {
        return vec![((0, 0), (1, 0))];
    }
    if z > deepest(region, layer) {
        return Vec::new();
    }
    let rows = TileSet::Crs84.matrix(z).1;
    let globe = BBox { west: -180.0, south: -90.0, east: 180.0, north: 90.0 };
    let ranges = region.bounds.clipped_to(&globe).into_iter().map(|part| {
        let ((x0, r0), (x1, r1)) = TileSet::Crs84.tiles_over(&part, z);
        ((x0, rows - 1 - r1), (x1, rows - 1 - r0))
    });
    ranges.collect()
}

/// Whether tile `(z, x, y)` exists.
pub fn exists(region: &Region, layer: Layer, (z, x, y): (u32, u64, u64)) -> bool {
    let within = |&((x0, y0), (x1, y1)): &((u64, u64), (u64, u64))| (x0..=x1).contains(&x) && (y0..=y1).contains(&y);
    available(region, layer, z).iter().any(within)
}

/// Which of tile `(z, x, y)`'s four children exist.
fn children(region: &Region, layer: Layer, (z, x, y): (u32, u64, u64)) -> Children {
    let quarters = [
        (0, 0, Children::SOUTH_WEST),
        (1, 0, Children::SOUTH_EAST),
        (0, 1, Children::NORTH_WEST),
        (1, 1, Children::NORTH_EAST),
    ];
    let bits = quarters.iter().filter(|&&(dx, dy, _)| exists(region, layer, (z + 1, 2 * x + dx, 2 * y + dy)));
    Children(bits.map(|q| q.2).sum())
}

/// The `layer.json` of `layer` over `region`.
fn document(region: &Region, layer: Layer) -> Value {
    let b = region.bounds.on_the_globe();
    let deepest = deepest(region, layer);
    let range = |&((x0, y0), (x1, y1)): &((u64, u64), (u64, u64))| json!({ "startX": x0, "startY": y0, "endX": x1, "endY": y1 });
    let available: Vec<Value> =
        (0..=deepest).map(|z| Value::Array(available(region, layer, z).iter().map(range).collect())).collect();
    json!({
        "tilejson": "2.1.0",
        "name": format!("{} {}", region.name, layer.name()),
        "description": format!("{} as Cesium heightmap terrain: 0.2 m steps, 0 m where there is no data", layer.name()),
        "version": "1.0.0",
        "format": "heightmap-1.0",
        "scheme": "tms",
        "projection": "EPSG:4326",
        "tiles": ["{z}/{x}/{y}.terrain"],
        "bounds": [b.west, b.south, b.east, b.north],
        "minzoom": 0,
        "maxzoom": deepest,
        "available": available,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tiles_over_the_demo_exist_to_its_finest_zoom_with_their_parents() {
        let region = crate::config::load(None).unwrap();
        // The DEM's spacing: 180° / 64 / 2^z at the equator no wider.
        let spacing_m = |z: u32| 20_037_508.342_789_244 / 64.0 / 2f64.powi(z as i32);
        let (dem, finest) = (deepest(&region, Layer::Dem), region.dem.georef().pixel_m());
        assert!(dem > 0 && spacing_m(dem) <= finest && spacing_m(dem - 1) > finest, "zoom {dem}, {finest} m");
        let deepest = deepest(&region, Layer::Cem);
        assert!(deepest >= dem, "the land cover may be finer");
        let doc = document(&region, Layer::Cem);
        assert_eq!(doc["available"].as_array().unwrap().len() as u32, deepest + 1);
        assert_eq!(doc["available"][0][0], json!({ "startX": 0, "startY": 0, "endX": 1, "endY": 0 }));
        // The demo (10–10.25° E, 46.3–46.45° N) lies in zoom 1's tile of
        // 0–90° E, 0–90° N: x 2, y 1 from the south.
        assert_eq!(doc["available"][1][0], json!({ "startX": 2, "startY": 1, "endX": 2, "endY": 1 }));
        // Each existing tile's parent exists and says so in its mask.
        for z in 1..=deepest {
            let [((x0, y0), (x1, y1))] = available(&region, Layer::Cem, z)[..] else { panic!("one range") };
            for (x, y) in (x0..=x1).flat_map(|x| (y0..=y1).map(move |y| (x, y))) {
                let parent = (z - 1, x / 2, y / 2);
                assert!(exists(&region, Layer::Cem, parent), "{z}/{x}/{y}");
                let bit = 1 << ((x % 2) + 2 * (y % 2));
                assert_ne!(children(&region, Layer::Cem, parent).0 & bit, 0, "{z}/{x}/{y}");
            }
        }
        assert!(!exists(&region, Layer::Cem, (deepest + 1, 0, 0)));
        assert_eq!(children(&region, Layer::Cem, (deepest, 0, 0)), Children(0));
        assert!(!exists(&region, Layer::Cem, (1, 0, 0)));
    }

    #[test]
    fn a_region_across_the_antimeridian_has_tiles_on_both_sides_only() {
        let mut region = crate::config::load(None).unwrap();
        region.bounds = BBox { west: 179.5, south: -17.0, east: 180.5, north: -16.0 };
        let doc = document(&region, Layer::Dem);
        // Zoom 8: tiles of 0.703125°; 179.5° E is column 511, 180.5° (−179.5°)
        // column 0; −17° to −16° are rows 103 to 105 from the south.
        let z8 = json!([
            { "startX": 0, "startY": 103, "endX": 0, "endY": 105 },
            { "startX": 511, "startY": 103, "endX": 511, "endY": 105 }
        ]);
        assert_eq!(doc["available"][8], z8);
        assert!(exists(&region, Layer::Dem, (8, 511, 104)) && exists(&region, Layer::Dem, (8, 0, 103)));
        assert!(!exists(&region, Layer::Dem, (8, 256, 103)), "not the whole band of latitudes");
    }

    #[test]
    fn neighbours_share_their_edge_samples_and_rows_count_from_the_south() {
        let region = crate::config::load(None).unwrap();
        let (a, east) = (tile_grid(&region, (9, 540, 387)).unwrap(), tile_grid(&region, (9, 541, 387)).unwrap());
        assert_eq!(a.lon.coord(SAMPLES - 1), east.lon.coord(0));
        assert_eq!(a.lat.coords(), east.lat.coords());
        let north = tile_grid(&region, (9, 540, 388)).unwrap();
        assert_eq!(north.lat.coord(SAMPLES - 1), a.lat.coord(0));
        // Tile (0, 0, 0) is the western hemisphere, its first row the north pole.
        let west = tile_grid(&region, (0, 0, 0)).unwrap();
        assert_eq!((west.lon.coord(0), west.lat.coord(0), west.lon.coord(SAMPLES - 1)), (-180.0, 90.0, 0.0));
        assert!(tile_grid(&region, (0, 2, 0)).is_err() && tile_grid(&region, (0, 0, 1)).is_err());
    }
}
