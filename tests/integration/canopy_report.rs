//! The pictures and figures of `docs/canopy.md`, ignored in normal runs:
//! `cargo test --test integration canopy_report -- --ignored --nocapture`
//! writes `docs/canopy/*.png` and prints the statistics the page quotes.

use crate::canopy::clouds;
use crate::common;
use std::sync::Arc;
use sylva::canopy::TiledProxy;
use sylva::cem::{self, Layer};
use sylva::grid::{BBox, SampleGrid};
use sylva::lidar::{self, Options};
use sylva::server::products::{self, Encoding, Product};
use sylva::server::wms::request::MapLayer;

/// 128 × 128 samples 0.5 m apart in the forest of the demo region.
fn demo_forest_edge(demo: &sylva::region::Region) -> SampleGrid {
    let b = demo.bounds;
    let coarse = b.point_grid(120, 120, &demo.tiles).expect("grid");
    let cover = cem::compute(demo, &coarse, &[Layer::Cover]).expect("cover").cover.expect("cover");
    let edge = (10..110)
        .flat_map(|y| (10..110).map(move |x| (x, y)))
        .find(|&(x, y)| cover.get(x, y) == 1.0 && cover.get(x + 1, y) < 0.5 && cover.get(x - 3, y) == 1.0)
        .expect("a forest edge");
    let (lon, lat) = (coarse.lon.coord(edge.0), coarse.lat.coord(edge.1));
    let half_deg = 32.0 / sylva::geo::METRES_PER_DEGREE;
    let half_lon = half_deg / lat.to_radians().cos();
    let bbox = BBox { west: lon - half_lon, east: lon + half_lon, south: lat - half_deg, north: lat + half_deg };
    bbox.point_grid(128, 128, &demo.tiles).expect("grid")
}

#[test]
#[ignore = "writes docs/canopy/*.png"]
fn write_canopy_report() {
    let out = common::repo().join("docs/canopy");
    std::fs::create_dir_all(&out).expect("docs/canopy");
    let mut demo = common::demo();
    let grid = demo_forest_edge(&demo);
    let (w, h) = (grid.width() - 1, grid.height() - 1);
    println!(
        "demo grid: lon {:.6}..{:.6}, lat {:.6}..{:.6}",
        grid.lon.coord(0),
        grid.lon.coord(w),
        grid.lat.coord(h),
        grid.lat.coord(0)
    );
    let relief = |region: &sylva::region::Region, name: &str| {
        let product = Product::Image { layer: MapLayer::Relief, grid, encoding: Encoding::Rgba };
        let png = products::compute(region, &product).expect("relief").bytes;
        std::fs::write(out.join(format!("demo_{name}.png")), &png).expect("write");
        println!("demo_{name}.png: {} bytes", png.len());
    };
    relief(&demo, "procedural");
    println!("procedural: {}", demo.proxy.describe());
    for (name, files, cell_m) in clouds() {
        let (model, set) = lidar::build(&Options::new(files, cell_m)).expect("proxy");
        println!("== {name} (resolution {cell_m} m)\n{}", model.report(&set));
        // 1 m texels over 192 m: the CHM's middle beside the tiles as laid out.
        let level = (1.0 / cell_m).log2().round() as usize;
        let cells = (192.0 / set.layout().tile_m()).ceil() as usize;
        let preview = model.preview_png(&set, cells, level).expect("preview");
        std::fs::write(out.join(format!("{name}.png")), &preview).expect("write");
        println!("{name}.png: {} bytes", preview.len());
        demo.proxy = Arc::new(TiledProxy::new(name, set, 1));
        relief(&demo, name);
    }
}
