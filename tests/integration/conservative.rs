//! Conservative acceleration data, checked exhaustively on real tiles: no
//! safety zone and no mipmap texel lies below any surface sample (or any point
//! of the bilinear surface) it covers. The checks use plain loops, not the
//! van Herk filter under test.

use crate::common::{self, Rng};
use sylva::cem::accel::{MaxMipmap, ZONE_FAR, ZONE_NEAR};
use sylva::cem::{self, Layer};
use sylva::grid::TileId;
use sylva::raster::Raster;
use sylva::region::Region;

/// Maximum over the `(2r+1)²` square around each sample of `src`'s centre
/// (`src` has `margin` extra samples per side), by two naive passes.
fn naive_zone(src: &Raster<f32>, margin: usize, r: usize) -> Raster<f32> {
    let (w, h) = (src.width() - 2 * margin, src.height() - 2 * margin);
    let rows = Raster::from_fn(w, src.height(), |x, y| {
        (x + margin - r..=x + margin + r).map(|sx| src.get(sx, y)).fold(f32::NAN, f32::max)
    });
    Raster::from_fn(w, h, |x, y| (y + margin - r..=y + margin + r).map(|sy| rows.get(x, sy)).fold(f32::NAN, f32::max))
}

fn check_tile(region: &Region, tile: TileId) {
    let grid = region.tiles.tile_samples(tile, 0);
    let p = cem::compute(region, &grid, &[Layer::Cem, Layer::Max4, Layer::Max32]).expect("tile");
    let around = cem::compute(region, &grid.grown(ZONE_FAR), &[Layer::Cem]).expect("around");
    let around = around.cem.expect("cem");
    let (max4, max32) = (p.max4.expect("max4"), p.max32.expect("max32"));
    for (zone, r) in [(&max4, ZONE_NEAR), (&max32, ZONE_FAR)] {
        let truth = naive_zone(&around, ZONE_FAR, r);
        for (i, (&z, &t)) in zone.data().iter().zip(truth.data()).enumerate() {
            assert!(z >= t || t.is_nan(), "{}: zone {r} at {i} is {z} below the surface {t}", region.name);
            assert!(
                z == t || (z.is_nan() && t.is_nan()),
                "{}: zone {r} at {i} is {z}, not the maximum {t}",
                region.name
            );
        }
    }
    check_mipmap(&p.cem.expect("cem"), &region.name);
}

fn check_mipmap(cem: &Raster<f32>, name: &str) {
    let mip = MaxMipmap::build(cem);
    let mut rng = Rng(5);
    for cy in 0..cem.height() - 1 {
        for cx in 0..cem.width() - 1 {
            let c = [cem.get(cx, cy), cem.get(cx + 1, cy), cem.get(cx, cy + 1), cem.get(cx + 1, cy + 1)];
            // Corner samples and a random point of the bilinear patch.
            let (u, v) = (rng.below(1000) as f32 / 1000.0, rng.below(1000) as f32 / 1000.0);
            let inside = (1.0 - v) * ((1.0 - u) * c[0] + u * c[1]) + v * ((1.0 - u) * c[2] + u * c[3]);
            let top = c.iter().copied().fold(inside, f32::max);
            for level in 0..mip.levels() {
                let b = mip.bound(level, cx >> level, cy >> level);
                assert!(b >= top || top.is_nan(), "{name}: mip level {level} cell ({cx}, {cy}) bound {b} < {top}");
            }
        }
    }
}

#[test]
fn demo_bounds_are_conservative_and_tight() {
    let demo = common::demo();
    let b = demo.bounds;
    let tile = demo.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 11);
    check_tile(&demo, tile);
}

#[test]
fn rmnp_and_mt_hood_bounds_are_conservative_and_tight() {
    for config in ["examples/rmnp.toml", "examples/mt_hood.toml"] {
        let region = common::region(config);
        let b = region.bounds;
        check_tile(&region, region.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 9));
    }
}
