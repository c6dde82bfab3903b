//! Leave out what is not needed: stages are counted, not timed.

use crate::common;
use sylva::cem::{self, Layer, Stage};
use sylva::raster::Raster;

/// Forest in the east half only (cover 0 % west of 10.5 E, 100 % east of it).
fn half_forest() -> sylva::region::Region {
    let dem = Raster::from_fn(200, 200, |x, y| 800.0 + (x + y) as f32);
    let cover = Raster::from_fn(200, 200, |x, _| if x < 100 { 0.0 } else { 100.0 });
    common::synthetic(dem, Some(cover), 10.0025, 45.9975, 0.005)
}

#[test]
fn a_tile_without_forest_does_no_cover_or_canopy_work() {
    let region = half_forest();
    let runs = |lon: f64| {
        let tile = region.tiles.tile_containing(lon, 45.5, 12);
        cem::compute(&region, &region.tiles.tile_samples(tile, 16), &Layer::ALL).expect("tile").stats
    };
    let open = runs(10.2);
    assert_eq!((open.runs(Stage::Elevation), open.runs(Stage::Landcover)), (1, 1));
    assert_eq!((open.runs(Stage::Cover), open.runs(Stage::Canopy), open.runs(Stage::Combine)), (0, 0, 0));
    let forest = runs(10.8);
    assert_eq!((forest.runs(Stage::Cover), forest.runs(Stage::Canopy), forest.runs(Stage::Combine)), (1, 1, 1));
}

#[test]
fn an_all_nodata_tile_stops_after_the_elevation_stage() {
    let demo = common::demo();
    let tile = demo.tiles.tile_containing(-150.0, -40.0, 9);
    let stats = cem::compute(&demo, &demo.tiles.tile_samples(tile, 32), &Layer::ALL).expect("tile").stats;
    for stage in Stage::ALL {
        assert_eq!(stats.runs(stage), u32::from(stage == Stage::Elevation), "{}", stage.name());
    }
}

#[test]
fn only_the_stages_a_layer_needs_run() {
    let demo = common::demo();
    let b = demo.bounds;
    let tile = demo.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 11);
    let grid = demo.tiles.tile_samples(tile, 0);
    let ran = |layers: &[Layer]| {
        let s = cem::compute(&demo, &grid, layers).expect("tile").stats;
        Stage::ALL.iter().filter(|&&st| s.runs(st) > 0).map(|st| st.name()).collect::<Vec<_>>()
    };
    assert_eq!(ran(&[Layer::Dem]), ["elevation"]);
    assert_eq!(ran(&[Layer::Cover]), ["elevation", "landcover", "cover"]);
    assert_eq!(ran(&[Layer::Cem]), ["elevation", "landcover", "cover", "canopy", "combine"]);
    assert_eq!(ran(&[Layer::Max4]), ["elevation", "landcover", "cover", "canopy", "combine", "zones"]);
}

#[test]
fn forest_types_add_no_canopy_work_where_there_is_no_forest() {
    // Mt Hood's summit is rock and ice; the region has two forest types.
    let hood = common::region("examples/mt_hood_forest_types.toml");
    let tile = hood.tiles.tile_containing(-121.6960, 45.3736, 14);
    let stats = cem::compute(&hood, &hood.tiles.tile_samples(tile, 16), &Layer::ALL).expect("tile").stats;
    assert_eq!((stats.runs(Stage::Elevation), stats.runs(Stage::Landcover)), (1, 1));
    assert_eq!((stats.runs(Stage::Cover), stats.runs(Stage::Canopy), stats.runs(Stage::Combine)), (0, 0, 0));
}
