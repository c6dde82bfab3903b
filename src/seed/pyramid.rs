//! The tile pyramids a seed fills, one per way the server hands out tiles:
//! World Wind's (the region's tiling, `/tiles`, in the data formats), the
//! quadtree sets of 256-pixel tiles (`xyz`: WebMercatorQuad, `/xyz` and
//! WMTS; `crs84`: WorldCRS84Quad, WMTS) and Cesium's terrain (`/cesium`).
//!
//! Each is a quadtree of [`TileId`]s — a tile's children double its row and
//! column — whose rows count from the south (World Wind, Cesium's TMS rows)
//! or from the north (the quadtree sets); a quadtree tile `z/x/y` is
//! `TileId { level: z, row: y, col: x }`. A pyramid says which tiles its
//! level 0 has, the area a tile holds, which layers it carries, at which
//! levels it advertises and serves them, and the server's product for a
//! tile of a layer (its cache key and bytes).
//!
//! Invariants: a tile whose area meets the coverage only along an edge
//! holds none of it in a quadtree set or Cesium (their pixels are areas, or
//! the server lists no such terrain tile), so it is not seeded there; a
//! tile's footprint lies within its parent's, so pruning a parent never
//! loses a child.

use crate::cem::Layer;
use crate::grid::mercator::MercatorBox;
use crate::grid::quad::{TileSet, geographic_box};
use crate::grid::{Sector, TileGrid, TileId};
use crate::region::Region;
use crate::server::products::Product;
use crate::server::wms::request::{LAYERS, MapLayer};
use crate::server::{MAX_XYZ_ZOOM, cesium, extent, wmts};
use std::ops::RangeInclusive;

/// A pyramid of tiles a seed can fill.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pyramid {
    /// World Wind's tiles on the region's tiling, in the data formats.
    WorldWind(TileGrid),
    /// A quadtree set's tiles (PNG: Terrarium heights or a picture).
    Quad(TileSet),
    /// Cesium's heightmap terrain.
    Cesium,
}

/// The pyramids' names for `--grid` (and the lines of a tile list).
pub const NAMES: &str = "worldwind, xyz (WebMercatorQuad), crs84 (WorldCRS84Quad), cesium";

impl Pyramid {
    /// The pyramid named `name` (any case; the quadtree sets also by their
    /// OGC names); World Wind's on `tiles`.
    pub fn parse(name: &str, tiles: TileGrid) -> Option<Pyramid> {
        let all = [
            Pyramid::WorldWind(tiles),
            Pyramid::Quad(TileSet::WebMercator),
            Pyramid::Quad(TileSet::Crs84),
            Pyramid::Cesium,
        ];
        let named = |p: &Pyramid| {
            let ogc = match p {
                Pyramid::Quad(set) => Some(set.name()),
                _ => None,
            };
            [Some(p.name()), ogc].into_iter().flatten().any(|n| n.eq_ignore_ascii_case(name.trim()))
        };
        all.into_iter().find(named)
    }

    /// Its name: the directory its tiles are cached under (but World Wind's,
    /// whose tiles are under their layers').
    pub fn name(self) -> &'static str {
        match self {
            Pyramid::WorldWind(_) => "worldwind",
            Pyramid::Quad(TileSet::WebMercator) => "xyz",
            Pyramid::Quad(TileSet::Crs84) => "crs84",
            Pyramid::Cesium => "cesium",
        }
    }

    /// Rows and columns of level 0.
    pub fn level0(self) -> (u64, u64) {
        let (cols, rows) = match self {
            Pyramid::WorldWind(tiles) => return tiles.tiles_on_level(0),
            Pyramid::Quad(set) => set.matrix(0),
            Pyramid::Cesium => TileSet::Crs84.matrix(0),
        };
        (rows, cols)
    }

    /// An error, naming the tile as [`Pyramid::address`] does, unless `tile`
    /// exists.
    pub fn check(self, tile: TileId) -> Result<(), String> {
        let TileId { level, row, col } = tile;
        let set = match self {
            Pyramid::WorldWind(tiles) => return tiles.check(tile).map_err(|e| e.to_string()),
            Pyramid::Quad(set) => set,
            Pyramid::Cesium => TileSet::Crs84,
        };
        set.check(level, col, row).map_err(|_| {
            let (cols, rows) = set.matrix(level.min(crate::grid::quad::MAX_ZOOM));
            let address = self.address(tile);
            format!("tile {address} does not exist (zoom {level} has {cols} columns × {rows} rows)")
        })
    }

    /// The area an existing tile holds, for testing it against a coverage:
    /// its sector, a hair smaller where an edge holds nothing (the module's
    /// invariants).
    pub fn footprint(self, tile: TileId) -> Sector {
        let TileId { level, row, col } = tile;
        let area = match self {
            Pyramid::WorldWind(tiles) => return tiles.sector(tile),
            Pyramid::Quad(TileSet::WebMercator) => MercatorBox::tile(level, col, row).geographic(),
            Pyramid::Quad(TileSet::Crs84) => geographic_box(level, col, row),
            Pyramid::Cesium => cesium::tile_box((level, col, row)),
        };
        area.sector().grown(-EDGE_DEG, -EDGE_DEG)
    }

    /// Whether the pyramid carries `layer` (what its routes serve).
    pub fn carries(self, layer: MapLayer) -> bool {
        match (self, layer) {
            (Pyramid::WorldWind(_), layer) => matches!(layer, MapLayer::Data(_)),
            (Pyramid::Quad(TileSet::WebMercator), layer) => layer.in_quad_tiles(),
            (Pyramid::Quad(TileSet::Crs84), layer) => wmts::offered().any(|l| l == layer),
            (Pyramid::Cesium, MapLayer::Data(l)) => cesium::LAYERS.contains(&l),
            (Pyramid::Cesium, _) => false,
        }
    }

    /// The names of the layers it carries.
    pub fn layer_names(self) -> String {
        let data = Layer::ALL.into_iter().map(MapLayer::Data);
        let all = data.chain(LAYERS.into_iter().filter(|l| l.is_picture()));
        let names: Vec<&str> = all.filter(|&l| self.carries(l)).map(MapLayer::name).collect();
        names.join(", ")
    }

    /// The levels at which the server advertises `layer` over `region`, for a
    /// pyramid other than World Wind's (whose levels are the operator's to
    /// choose): from zoom 0, a quadtree set's every matrix WMTS lists, or
    /// to the layer's TileJSON max zoom where deeper (or WMTS does not offer
    /// it); Cesium's `layer.json` zooms; an error where the region has none.
    pub fn advertised(self, region: &Region, layer: MapLayer) -> Option<Result<RangeInclusive<u32>, String>> {
        match (self, layer) {
            (Pyramid::WorldWind(_), _) => None,
            (Pyramid::Quad(set), _) => Some(match extent::extent(region, layer, set) {
                Some(e) => {
                    let in_wmts = wmts::offered().any(|l| l == layer);
                    let matrices = wmts::deepest_matrix(region, set).filter(|_| in_wmts);
                    Ok(0..=e.max_zoom.max(matrices.unwrap_or(0)))
                }
                None => Err(format!("the region lies beyond {}'s latitudes", set.name())),
            }),
            (Pyramid::Cesium, MapLayer::Data(l)) => Some(Ok(0..=cesium::deepest(region, l))),
            (Pyramid::Cesium, _) => Some(Err("Cesium terrain carries heights only".into())),
        }
    }

    /// The levels at which the server answers `layer`'s tiles: any of World
    /// Wind's and of the `/xyz` path's, the matrices of WMTS's geographic
    /// set, Cesium's listed zooms.
    pub fn served_levels(self, region: &Region, layer: MapLayer) -> Option<RangeInclusive<u32>> {
        match self {
            Pyramid::WorldWind(_) => Some(0..=TileGrid::MAX_LEVEL),
            Pyramid::Quad(TileSet::WebMercator) => Some(0..=MAX_XYZ_ZOOM),
            Pyramid::Quad(TileSet::Crs84) => Some(0..=wmts::deepest_matrix(region, TileSet::Crs84)?),
            Pyramid::Cesium => self.advertised(region, layer)?.ok(),
        }
    }

    /// Whether `layer` is served at `level`.
    pub fn serves_level(self, region: &Region, layer: MapLayer, level: u32) -> bool {
        self.served_levels(region, layer).is_some_and(|l| l.contains(&level))
    }

    /// Whether the server answers `tile` of `layer` (an existing tile): at a
    /// level it serves, within a WMTS layer's limits or Cesium's list.
    pub fn serves(self, region: &Region, layer: MapLayer, tile: TileId) -> bool {
        let zxy = (tile.level, tile.col, tile.row);
        self.serves_level(region, layer, tile.level)
            && match (self, layer) {
                (Pyramid::Quad(TileSet::Crs84), _) => {
                    extent::extent(region, layer, TileSet::Crs84).is_some_and(|e| e.holds(TileSet::Crs84, zxy))
                }
                (Pyramid::Cesium, MapLayer::Data(l)) => cesium::exists(region, l, zxy),
                _ => true,
            }
    }

    /// The server's product for `tile` of `layer`; none for World Wind's,
    /// whose tiles come in the job's formats.
    pub fn product(self, layer: MapLayer, tile: TileId) -> Option<Product> {
        let zxy = (tile.level, tile.col, tile.row);
        match (self, layer) {
            (Pyramid::Quad(set), layer) => Some(Product::Quad { layer, set, zxy }),
            (Pyramid::Cesium, MapLayer::Data(layer)) => Some(Product::Terrain { layer, zxy }),
            _ => None,
        }
    }

    /// A tile's address as its URL and cache key write it: `level/row/col`
    /// (World Wind) or `z/x/y`.
    pub fn address(self, tile: TileId) -> String {
        match self {
            Pyramid::WorldWind(_) => tile.to_string(),
            _ => format!("{}/{}/{}", tile.level, tile.col, tile.row),
        }
    }

    /// The tile of an address written by [`Pyramid::address`].
    pub fn parse_address(self, text: &str) -> Option<TileId> {
        let t = super::progress::parse_tile(text)?;
        Some(match self {
            Pyramid::WorldWind(_) => t,
            _ => TileId::new(t.level, t.col, t.row),
        })
    }
}

/// How far a footprint's edges lie inside its tile's, degrees: the same at
/// every level (so a child's footprint lies within its parent's), 0.1 mm,
/// under a hundredth of a pixel at the deepest zoom served, far above
/// `f64`'s resolution at ±180°. (A coverage reaching less than this past a
/// tile's edge leaves that tile, and its sliver of data, unseeded.)
const EDGE_DEG: f64 = 1e-9;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::BBox;

    #[test]
    fn names_parse_and_addresses_read_back() {
        let tiles = TileGrid::new(36.0, 513).unwrap();
        for p in [Pyramid::WorldWind(tiles), Pyramid::Quad(TileSet::WebMercator), Pyramid::Quad(TileSet::Crs84)] {
            assert_eq!(Pyramid::parse(p.name(), tiles), Some(p));
        }
        assert_eq!(Pyramid::parse("WebMercatorQuad", tiles), Some(Pyramid::Quad(TileSet::WebMercator)));
        assert_eq!(Pyramid::parse("CESIUM", tiles), Some(Pyramid::Cesium));
        assert_eq!(Pyramid::parse("tms", tiles), None);
        assert_eq!(Pyramid::parse("", tiles), None);
        let t = TileId::new(12, 1400, 655);
        assert_eq!(Pyramid::Quad(TileSet::WebMercator).address(t), "12/655/1400");
        assert_eq!(Pyramid::WorldWind(tiles).address(t), "12/1400/655");
        for p in [Pyramid::WorldWind(tiles), Pyramid::Cesium] {
            assert_eq!(p.parse_address(&p.address(t)), Some(t));
        }
        let err = Pyramid::Quad(TileSet::WebMercator).check(TileId::new(3, 1, 8)).unwrap_err();
        assert_eq!(err, "tile 3/8/1 does not exist (zoom 3 has 8 columns × 8 rows)");
        assert!(Pyramid::Quad(TileSet::Crs84).check(TileId::new(1, 2, 0)).is_err());
        assert_eq!(Pyramid::Quad(TileSet::Crs84).level0(), (1, 2));
    }

    #[test]
    fn footprints_are_the_tiles_areas_less_their_edges_and_nest() {
        // XYZ 1/1/0 is the north-east quarter of Web Mercator's square.
        let xyz = Pyramid::Quad(TileSet::WebMercator);
        let f = xyz.footprint(TileId::new(1, 0, 1));
        assert!(f.min_lon > 0.0 && f.min_lon < 1e-6 && f.max_lon < 180.0 && f.max_lon > 179.999, "{f:?}");
        assert!(f.min_lat > 0.0 && (f.max_lat - 85.0511).abs() < 1e-3, "{f:?}");
        // Cesium's rows count from the south, the CRS84 set's from the north.
        let south = Pyramid::Cesium.footprint(TileId::new(1, 0, 0));
        let north = Pyramid::Quad(TileSet::Crs84).footprint(TileId::new(1, 0, 0));
        assert!(south.max_lat < 0.0 && south.min_lat > -90.0 && north.min_lat > 0.0, "{south:?} {north:?}");
        // A tile touching a box along an edge does not meet it; World Wind's
        // (whose edge samples lie on the edge) does.
        let west_of = BBox { west: -10.0, south: 1.0, east: 0.0, north: 2.0 }.sector();
        assert!(!f.intersects(&west_of));
        let tiles = TileGrid::new(36.0, 513).unwrap();
        assert_eq!(Pyramid::WorldWind(tiles).footprint(TileId::new(0, 2, 5)), tiles.sector(TileId::new(0, 2, 5)));
        // A box reaching 1e-4° past a zoom-1 edge meets the zoom-1 tile
        // beyond it as it meets every tile beneath along that edge:
        // children's footprints lie within their parents'.
        let sliver = BBox { west: -1.0, south: 10.0, east: 1e-4, north: 11.0 }.sector();
        for p in [xyz, Pyramid::Quad(TileSet::Crs84), Pyramid::Cesium] {
            // The zoom-1 tile east of 0° over 10.5° N.
            let mut tile = match p {
                Pyramid::Cesium => TileId::new(1, 1, 2),
                Pyramid::Quad(TileSet::Crs84) => TileId::new(1, 0, 2),
                _ => TileId::new(1, 0, 1),
            };
            for _ in 0..20 {
                let parent = p.footprint(tile);
                assert!(parent.intersects(&sliver), "{p:?} {tile}");
                // Within rounding (edges computed from each tile's own index).
                let within = parent.grown(1e-12, 1e-12);
                for child in tile.children().map(|c| p.footprint(c)) {
                    let inside = within.min_lon <= child.min_lon && child.max_lon <= within.max_lon;
                    let rows = within.min_lat <= child.min_lat && child.max_lat <= within.max_lat;
                    assert!(inside && rows, "{p:?} {tile}: {child:?} in {parent:?}");
                }
                // The western child that holds the sliver's latitudes.
                let west = tile.children().into_iter().filter(|c| c.col == 2 * tile.col);
                let lat = |c: &TileId| (p.footprint(*c).min_lat..p.footprint(*c).max_lat).contains(&10.5);
                tile = west.into_iter().find(lat).unwrap();
            }
        }
    }

    #[test]
    fn each_pyramid_carries_and_serves_what_its_server_route_does() {
        let tiles = TileGrid::new(36.0, 513).unwrap();
        assert_eq!(Pyramid::Cesium.layer_names(), "dem, cem");
        assert_eq!(Pyramid::Quad(TileSet::WebMercator).layer_names(), "dem, canopy, cem, max4, max32, colour, relief");
        assert_eq!(Pyramid::Quad(TileSet::Crs84).layer_names(), "dem, canopy, cem, colour, relief");
        assert_eq!(Pyramid::WorldWind(tiles).layer_names(), "dem, cover, canopy, cem, surface, max4, max32");
        let region = crate::config::load(None).unwrap();
        // Every matrix of WMTS's sets, for any layer (GDAL reads each at the deepest).
        let dem = MapLayer::Data(Layer::Dem);
        for set in TileSet::ALL {
            let deepest = wmts::deepest_matrix(&region, set).unwrap();
            assert!(deepest > extent::extent(&region, dem, set).unwrap().max_zoom);
            assert_eq!(Pyramid::Quad(set).advertised(&region, dem).unwrap().unwrap(), 0..=deepest);
        }
        let max4 = MapLayer::Data(Layer::Max4);
        let e = extent::extent(&region, max4, TileSet::WebMercator).unwrap();
        assert_eq!(Pyramid::Quad(TileSet::WebMercator).advertised(&region, max4).unwrap().unwrap(), 0..=e.max_zoom);
        assert_eq!(
            Pyramid::Quad(TileSet::WebMercator).served_levels(&region, MapLayer::Relief),
            Some(0..=MAX_XYZ_ZOOM)
        );
        assert!(Pyramid::Cesium.advertised(&region, MapLayer::Relief).unwrap().is_err());
        let cem = MapLayer::Data(Layer::Cem);
        assert_eq!(Pyramid::Cesium.served_levels(&region, cem), Some(0..=cesium::deepest(&region, Layer::Cem)));
        assert!(Pyramid::WorldWind(tiles).advertised(&region, cem).is_none());
        // WMTS's limits: the demo's zoom-12 geographic tiles are columns
        // 4323 to 4329, rows 991 to 994 (its box's corners in tiles of
        // 180°/4096 from the north-west: 4323.6, 4329.2, 991.0, 994.4).
        let crs84 = Pyramid::Quad(TileSet::Crs84);
        assert!(crs84.serves(&region, cem, TileId::new(12, 991, 4329)));
        assert!(!crs84.serves(&region, cem, TileId::new(12, 990, 4323)));
        assert!(!crs84.serves(&region, cem, TileId::new(12, 992, 4330)));
        assert!(!crs84.serves(&region, cem, TileId::new(30, 0, 0)));
        let deepest = wmts::deepest_matrix(&region, TileSet::Crs84).unwrap();
        assert_eq!(crs84.served_levels(&region, MapLayer::Data(Layer::Dem)), Some(0..=deepest));
        // Cesium's: both zoom-0 tiles, the region's below.
        assert!(Pyramid::Cesium.serves(&region, cem, TileId::new(0, 0, 0)));
        assert!(!Pyramid::Cesium.serves(&region, cem, TileId::new(12, 0, 0)));
    }
}
