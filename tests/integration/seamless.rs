//! Seamlessness: a tile, with any halo, equals the same window of a whole-area
//! build, bitwise, for every layer — through the close, the blur, the canopy
//! and the 32-sample maximum — and neighbouring tiles agree on shared samples.
//! The shaded relief, whose shading depends on latitude, too.

use crate::common::{self, Rng, assert_same};
use image::RgbaImage;
use sylva::cem::{self, Layer, Products};
use sylva::grid::{BBox, SampleGrid, TileId};
use sylva::raster::{Raster, Window};
use sylva::region::Region;
use sylva::server::products::{self, Encoding, Product};
use sylva::server::wms::request::MapLayer;

const FLOAT_LAYERS: [Layer; 6] = [Layer::Dem, Layer::Cover, Layer::Canopy, Layer::Cem, Layer::Max4, Layer::Max32];

fn float(p: &Products, layer: Layer) -> &Raster<f32> {
    match p.samples(layer) {
        Some(sylva::encode::Samples::Float(r)) => r,
        _ => panic!("{} missing", layer.name()),
    }
}

/// The 3 × 3 block of tiles around `centre`, built in one computation.
fn build_around(region: &Region, centre: TileId) -> Products {
    cem::compute(region, &grid_around(region, centre), &Layer::ALL).expect("build")
}

/// The grid of the 3 × 3 block of tiles around `centre`.
fn grid_around(region: &Region, centre: TileId) -> SampleGrid {
    let t = &region.tiles;
    let sw = t.sector(TileId::new(centre.level, centre.row - 1, centre.col - 1));
    let ne = t.sector(TileId::new(centre.level, centre.row + 1, centre.col + 1));
    let n = 3 * (t.samples() as usize - 1) + 1;
    let bbox = BBox { west: sw.min_lon, south: sw.min_lat, east: ne.max_lon, north: ne.max_lat };
    let grid = bbox.point_grid(n, n, t).expect("grid");
    assert_eq!(grid.lon.first, (centre.col as i64 - 1) * (t.samples() as i64 - 1), "the build is on the tile lattice");
    grid
}

/// Random tiles near the region's centre on `level`, each checked against
/// the build around it with a random halo.
fn check(region: &Region, level: u32, cases: usize, seed: u64) {
    let mut rng = Rng(seed);
    let b = region.bounds;
    for _ in 0..cases {
        let lon = b.west + (b.east - b.west) * (0.3 + 0.4 * rng.below(1000) as f64 / 1000.0);
        let lat = b.south + (b.north - b.south) * (0.3 + 0.4 * rng.below(1000) as f64 / 1000.0);
        let centre = region.tiles.tile_containing(lon, lat, level);
        check_tile(region, centre, [0usize, 1, 7, 32, 100][rng.below(5) as usize]);
    }
}

/// The tile `centre` with `halo` equals the same window of the build of the
/// 3 × 3 tiles around it, in every layer; the tile has forest.
pub fn check_tile(region: &Region, centre: TileId, halo: usize) {
    let n = region.tiles.samples() as usize;
    let build = build_around(region, centre);
    let tile = cem::compute(region, &region.tiles.tile_samples(centre, halo), &Layer::ALL).expect("tile");
    let window = Window::new((n - 1 - halo) as i64, (n - 1 - halo) as i64, n + 2 * halo, n + 2 * halo);
    for layer in FLOAT_LAYERS {
        let what = format!("{} tile {centre} halo {halo} layer {}", region.name, layer.name());
        assert_same(float(&tile, layer), &float(&build, layer).crop(window, f32::NAN), &what);
    }
    let surface = build.surface.as_ref().expect("surface").crop(window, 0);
    assert_eq!(tile.surface.as_ref(), Some(&surface), "{} tile {centre} surface", region.name);
    assert!(float(&tile, Layer::Cover).data().iter().any(|&c| c > 0.0), "{}: pick tiles with forest", region.name);
}

#[test]
fn demo_tiles_equal_windows_of_a_build() {
    let demo = common::demo();
    check(&demo, 9, 2, 11);
    check(&demo, 12, 2, 12);
}

#[test]
fn rmnp_tiles_equal_windows_of_a_build() {
    let rmnp = common::region("examples/rmnp.toml");
    check(&rmnp, 6, 1, 21);
    check(&rmnp, 9, 2, 22);
}

#[test]
fn tiles_with_a_lidar_proxy_equal_windows_of_a_build() {
    // Texels bilinear at 0.24 m spacing (level 15), mip levels blended at 1.9 m (level 12).
    let nz = common::region("examples/nz_lidar.toml");
    check(&nz, 15, 1, 31);
    check(&nz, 12, 1, 32);
}

#[test]
fn neighbours_share_edge_samples_exactly() {
    let demo = common::demo();
    let b = demo.bounds;
    let t = demo.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 11);
    let n = demo.tiles.samples() as usize;
    let get = |row, col| {
        cem::compute(&demo, &demo.tiles.tile_samples(TileId::new(11, row, col), 0), &Layer::ALL).expect("tile")
    };
    let (sw, se, nw) = (get(t.row, t.col), get(t.row, t.col + 1), get(t.row + 1, t.col));
    for layer in FLOAT_LAYERS {
        let (a, east, north) = (float(&sw, layer), float(&se, layer), float(&nw, layer));
        assert_same(
            &a.crop(Window::new(n as i64 - 1, 0, 1, n), 0.0),
            &east.crop(Window::new(0, 0, 1, n), 0.0),
            layer.name(),
        );
        assert_same(
            &a.crop(Window::new(0, 0, n, 1), 0.0),
            &north.crop(Window::new(0, n as i64 - 1, n, 1), 0.0),
            layer.name(),
        );
    }
}

/// The relief picture of `product`, decoded.
fn relief(region: &Region, product: Product) -> RgbaImage {
    let png = products::compute(region, &product).expect("relief").bytes;
    image::load_from_memory(&png).expect("a relief PNG").into_rgba8()
}

/// The relief of tile `id` with `halo`.
fn relief_tile(region: &Region, id: TileId, halo: usize) -> RgbaImage {
    picture_tile(region, RELIEF, id, halo)
}

/// The relief picture.
const RELIEF: (MapLayer, Encoding) = (MapLayer::Relief, Encoding::Rgba);

/// The picture `(layer, encoding)` of tile `id` with `halo`.
fn picture_tile(region: &Region, (layer, encoding): (MapLayer, Encoding), id: TileId, halo: usize) -> RgbaImage {
    relief(region, Product::Tile { layer, id, halo, encoding })
}

/// The `w × h` pixels of `img` from `(x, y)`.
fn pixels(img: &RgbaImage, x: u32, y: u32, w: u32, h: u32) -> RgbaImage {
    image::imageops::crop_imm(img, x, y, w, h).to_image()
}

/// Pixel-for-pixel equality; the first difference is reported.
fn assert_same_pixels(a: &RgbaImage, b: &RgbaImage, what: &str) {
    assert_eq!(a.dimensions(), b.dimensions(), "{what}: sizes differ");
    if let Some(((x, y, p), q)) = a.enumerate_pixels().zip(b.pixels()).find(|((_, _, p), q)| p != q) {
        panic!("{what}: pixel ({x}, {y}) is {:?} vs {:?}", p.0, q.0);
    }
}

/// Tile `t`'s picture agrees with its east and north neighbours' on the
/// shared column and row.
fn check_picture_neighbours(region: &Region, picture: (MapLayer, Encoding), t: TileId) {
    let n = region.tiles.samples();
    let (a, east, north) = (
        picture_tile(region, picture, t, 0),
        picture_tile(region, picture, TileId::new(t.level, t.row, t.col + 1), 0),
        picture_tile(region, picture, TileId::new(t.level, t.row + 1, t.col), 0),
    );
    let what = |side| format!("{} {} {t}: {side} edge", region.name, picture.0.name());
    assert_same_pixels(&pixels(&a, n - 1, 0, 1, n), &pixels(&east, 0, 0, 1, n), &what("east"));
    assert_same_pixels(&pixels(&a, 0, 0, n, 1), &pixels(&north, 0, n - 1, n, 1), &what("north"));
}

#[test]
fn relief_neighbours_share_edge_pixels_exactly() {
    // Regression: the shading's east–west spacing was taken at each tile's
    // middle latitude, so a row shared by north–south neighbours was shaded
    // with two spacings and differed by 1 in a few channels.
    let demo = common::demo();
    let b = demo.bounds;
    for level in [9, 11, 13] {
        let t = demo.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), level);
        check_picture_neighbours(&demo, RELIEF, t);
    }
}

#[test]
fn a_picture_without_data_of_its_own_is_absent() {
    // Its shading margin may reach the data; the picture would be empty
    // (a white JPEG where a client expects no tile).
    let demo = common::demo();
    let b = demo.bounds;
    let lat = 0.5 * (b.south + b.north);
    let step = 1e-4;
    let grid_west_of = |east_lon: f64, n: usize| {
        let east = east_lon + 0.5 * step;
        BBox { west: east - n as f64 * step, south: lat - 0.5 * step, east, north: lat + 0.5 * step }
            .area_grid(n, 1)
            .unwrap()
    };
    let has_data = |grid: &SampleGrid| {
        products::samples(&demo, grid, Layer::Dem).unwrap().0.is_some_and(|s| !s.view().all_nodata())
    };
    // The west edge of the data along the row, by bisection.
    let (mut inside, mut outside) = (0.5 * (b.west + b.east), b.west - 1.0);
    assert!(has_data(&grid_west_of(inside, 1)) && !has_data(&grid_west_of(outside, 1)));
    while inside - outside > 0.01 * step {
        let mid = 0.5 * (inside + outside);
        if has_data(&grid_west_of(mid, 1)) { inside = mid } else { outside = mid }
    }
    // Eight samples ending just west of it: no data of their own, the
    // margin's east column on the data.
    let grid = grid_west_of(outside - 0.5 * step, 8);
    assert!(!has_data(&grid) && has_data(&grid.grown(1)), "the margin alone reaches the data");
    for (layer, encoding) in
        [RELIEF, (MapLayer::Data(Layer::Dem), Encoding::Picture), (MapLayer::Data(Layer::Surface), Encoding::Picture)]
    {
        let product = Product::Image { layer, grid, encoding };
        assert!(products::compute(&demo, &product).unwrap().bytes.is_empty(), "{}: absent", layer.name());
    }
}

#[test]
fn pictures_of_data_layers_share_edge_pixels_exactly() {
    // What JPEG answers for a data layer: heights shaded with a margin, so
    // neighbours need no common range and still agree.
    let demo = common::demo();
    let b = demo.bounds;
    let t = demo.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 11);
    for layer in [Layer::Dem, Layer::Cem, Layer::Canopy, Layer::Cover, Layer::Surface, Layer::Max32] {
        let picture = (MapLayer::Data(layer), Encoding::Picture);
        check_picture_neighbours(&demo, picture, t);
        let img = picture_tile(&demo, picture, t, 0);
        let levels: std::collections::HashSet<[u8; 4]> = img.pixels().map(|p| p.0).collect();
        let least = if layer == Layer::Surface { 2 } else { 50 };
        assert!(levels.len() >= least, "{}: a picture, not a blank ({} colours)", layer.name(), levels.len());
    }
}

#[test]
fn relief_tiles_equal_windows_of_a_relief_build() {
    let demo = common::demo();
    let b = demo.bounds;
    let centre = demo.tiles.tile_containing(0.4 * b.west + 0.6 * b.east, 0.6 * b.south + 0.4 * b.north, 11);
    let grid = grid_around(&demo, centre);
    let build = relief(&demo, Product::Image { layer: MapLayer::Relief, grid, encoding: Encoding::Rgba });
    let n = demo.tiles.samples();
    // The centre with a halo, and its neighbours north and south, whose middle
    // latitudes are not the build's.
    for (row, halo) in [(0, 7), (1, 0), (-1, 0)] {
        let id = TileId::new(centre.level, centre.row.wrapping_add_signed(row), centre.col);
        let top = (1 - row) as u32 * (n - 1) - halo;
        let window = pixels(&build, n - 1 - halo, top, n + 2 * halo, n + 2 * halo);
        assert_same_pixels(&relief_tile(&demo, id, halo as usize), &window, &format!("relief {id} halo {halo}"));
    }
}

#[test]
fn rmnp_relief_neighbours_share_edge_pixels_exactly() {
    // The tiles of the audit that found the north–south seam.
    check_picture_neighbours(&common::region("examples/rmnp.toml"), RELIEF, TileId::new(12, 14830, 8452));
}

#[test]
fn quadtree_relief_tiles_equal_windows_of_a_build() {
    // Regression: a Web Mercator grid's rows were shaded with the north–south
    // spacing of the grid's middle; the build below has its middle at the
    // tile's southern edge, up to a few degrees from the tile's own (at zoom
    // 6 a channel differed by 2).
    use sylva::grid::mercator::{HALF_WORLD_M, MercatorBox, to_mercator};
    use sylva::grid::quad::TileSet;
    let demo = common::demo();
    let b = demo.bounds;
    let (lon, lat) = (0.5 * (b.west + b.east), 0.5 * (b.south + b.north));
    let (mx, my) = to_mercator(lon, lat);
    for z in [5, 6, 7, 8] {
        // The tile holding the region's middle and the box of it with its
        // southern neighbour, in each set.
        let size = 2.0 * HALF_WORLD_M / f64::from(1u32 << z);
        let (x, y) = (((mx + HALF_WORLD_M) / size) as u64, ((HALF_WORLD_M - my) / size) as u64);
        let tile_box = MercatorBox::of_tile(z, x, y).expect("tile");
        let mercator = MercatorBox { south: tile_box.south - size, ..tile_box }.area_grid(256, 512).expect("grid");
        let deg = 180.0 / f64::from(1u32 << z);
        let (col, row) = (((lon + 180.0) / deg) as u64, ((90.0 - lat) / deg) as u64);
        let (west, north) = (-180.0 + col as f64 * deg, 90.0 - row as f64 * deg);
        let geographic = BBox { west, south: north - 2.0 * deg, east: west + deg, north }.area_grid(256, 512).unwrap();
        for (set, (x, y), grid) in [(TileSet::WebMercator, (x, y), mercator), (TileSet::Crs84, (col, row), geographic)]
        {
            let build = relief(&demo, Product::Image { layer: MapLayer::Relief, grid, encoding: Encoding::Rgba });
            let tile = relief(&demo, Product::Quad { layer: MapLayer::Relief, set, zxy: (z, x, y) });
            assert_same_pixels(&tile, &pixels(&build, 0, 0, 256, 256), &format!("{set:?} relief {z}/{x}/{y}"));
        }
    }
}
