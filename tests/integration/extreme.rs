//! Stiff and extreme cases: no panic, no NaN where there is data, and the
//! error stated (16-bit clamping and quantization are reported).

use crate::common::{self, assert_same};
use sylva::cem::{self, Layer, Products};
use sylva::encode::{self, Format, Quantization, Samples};
use sylva::grid::{BBox, GridError, TileId};
use sylva::produce::{self, ProduceError};
use sylva::raster::{Raster, Window};

fn no_nan(r: &Raster<f32>, what: &str) {
    assert!(r.data().iter().all(|v| v.is_finite()), "{what}: non-finite sample");
}

/// A 1° × 1° DEM of 200² pixels around (10.5 E, 45.5 N).
fn square(f: impl Fn(usize, usize) -> f32) -> Raster<f32> {
    Raster::from_fn(200, 200, f)
}

fn tile_over(region: &sylva::region::Region, level: u32) -> (TileId, Products) {
    let tile = region.tiles.tile_containing(10.5, 45.5, level);
    let p = cem::compute(region, &region.tiles.tile_samples(tile, 8), &Layer::ALL).expect("tile");
    (tile, p)
}

#[test]
fn a_tile_spanning_minus_430_to_8850_m_keeps_its_range_in_16_bits() {
    let dem = square(|x, y| if (x + y) % 7 == 0 { 8850.0 } else { -430.0 + (x + y) as f32 * 20.0 });
    let region = common::synthetic(dem, Some(Raster::filled(200, 200, 60.0)), 10.0025, 45.9975, 0.005);
    let grid = BBox { west: 10.001, south: 45.001, east: 10.999, north: 45.999 }
        .point_grid(513, 513, &region.tiles)
        .expect("grid");
    let p = cem::compute(&region, &grid, &[Layer::Cem, Layer::Max32]).expect("tile");
    let cem = p.cem.expect("cem");
    no_nan(&cem, "cem");
    let (lo, hi) = cem.min_max().expect("data");
    assert!(lo < -300.0 && hi > 8800.0, "{lo}..{hi}");
    let q = Quantization::PNG16_HEIGHTS;
    let png = encode::encode(Layer::Cem, Samples::Float(&cem), &grid, Format::Png16, q).expect("png16");
    assert_eq!(png.clamped, 0, "-500 m .. 9330 m fits");
    let decoded = image::load_from_memory(&png.bytes).expect("png").into_luma16();
    let worst = decoded
        .pixels()
        .zip(cem.data())
        .map(|(c, &h)| (q.offset + q.scale * c.0[0] as f64 - h as f64).abs())
        .fold(0.0, f64::max);
    println!("png16 over {lo:.1}..{hi:.1} m: worst error {worst:.4} m (stated bound {:.3} m)", q.scale / 2.0);
    assert!(worst <= q.scale / 2.0 + 1e-6);
    no_nan(&p.max32.expect("max32"), "max32");
}

#[test]
fn a_1000_m_cliff_between_two_samples_is_bounded_and_finite() {
    let dem = square(|x, _| if x < 100 { 500.0 } else { 1500.0 });
    let region = common::synthetic(dem, None, 10.0025, 45.9975, 0.005);
    // Samples at the DEM's own spacing, two of them across the cliff.
    let bbox = BBox { west: 10.0025 + 0.005 * 90.0, east: 10.0025 + 0.005 * 109.0, north: 45.5, south: 45.4 };
    let grid = bbox.point_grid(20, 21, &region.tiles).expect("grid");
    let p = cem::compute(&region, &grid, &[Layer::Cem, Layer::Max4, Layer::Max32]).expect("cliff");
    let (cem, max4) = (p.cem.expect("cem"), p.max4.expect("max4"));
    no_nan(&cem, "cem");
    assert_eq!((cem.get(9, 10), cem.get(10, 10)), (500.0, 1500.0), "the cliff is between two samples");
    for x in 0..20 {
        let expect = if x >= 6 { 1500.0 } else { 500.0 };
        assert_eq!(max4.get(x, 10), expect, "zone at column {x}");
    }
    assert!(p.max32.expect("max32").data().iter().all(|&v| v == 1500.0));
}

#[test]
fn an_all_nodata_tile_is_nodata_in_every_layer_and_every_format() {
    let demo = common::demo();
    let tile = demo.tiles.tile_containing(-150.0, -40.0, 8);
    let grid = demo.tiles.tile_samples(tile, 0);
    let p = cem::compute(&demo, &grid, &Layer::ALL).expect("tile");
    assert!(p.cem.as_ref().expect("cem").all_nodata() && p.max32.as_ref().expect("max32").all_nodata());
    assert!(p.surface.as_ref().expect("surface").data().iter().all(|&s| s == sylva::cem::surface::NODATA));
    for format in [Format::Bil16, Format::Bil32, Format::Png16, Format::Tiff] {
        let e = encode::encode(Layer::Cem, p.samples(Layer::Cem).expect("cem"), &grid, format, demo.heights_16)
            .expect("encode");
        if format == Format::Bil32 {
            assert!(
                e.bytes.chunks(4).all(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")) == encode::NODATA_HEIGHT)
            );
        }
    }
}

#[test]
fn a_constant_tile_stays_constant() {
    let region = common::synthetic(square(|_, _| 1234.5), None, 10.0025, 45.9975, 0.005);
    let (_, p) = tile_over(&region, 9);
    for layer in [Layer::Dem, Layer::Cem, Layer::Max4, Layer::Max32] {
        let Some(Samples::Float(r)) = p.samples(layer) else { panic!() };
        assert!(r.data().iter().all(|&v| v == 1234.5), "{}", layer.name());
    }
}

#[test]
fn level_0_and_level_22_tiles_of_the_demo() {
    let demo = common::demo();
    let b = demo.bounds;
    let (lon, lat) = (0.5 * (b.west + b.east), 0.5 * (b.south + b.north));
    let coarse =
        cem::compute(&demo, &demo.tiles.tile_samples(demo.tiles.tile_containing(lon, lat, 0), 0), &[Layer::Cem])
            .expect("level 0");
    let cem0 = coarse.cem.expect("cem");
    let valid: Vec<f32> = cem0.data().iter().copied().filter(|v| !v.is_nan()).collect();
    assert!(!valid.is_empty() && valid.iter().all(|v| (300.0..4000.0).contains(v)), "{valid:?}");
    let deep_tile = demo.tiles.tile_containing(lon, lat, 22);
    let deep =
        cem::compute(&demo, &demo.tiles.tile_samples(deep_tile, 2), &[Layer::Cem, Layer::Canopy]).expect("level 22");
    let cem22 = deep.cem.expect("cem");
    no_nan(&cem22, "level 22");
    // 2 mm apart, neighbouring samples differ by millimetres, never by a step.
    let worst = (0..cem22.height())
        .flat_map(|y| (1..cem22.width()).map(move |x| (x, y)))
        .map(|(x, y)| (cem22.get(x, y) - cem22.get(x - 1, y)).abs())
        .fold(0.0, f32::max);
    assert!(worst < 0.05, "largest step between 2 mm neighbours: {worst} m");
}

/// A global DEM and a forest everywhere, for poles and the antimeridian.
fn globe() -> sylva::region::Region {
    let dem = Raster::from_fn(360, 180, |x, y| 1000.0 + 500.0 * ((x as f32 * 0.1).sin() + (y as f32 * 0.13).cos()));
    common::synthetic(dem, Some(Raster::filled(360, 180, 100.0)), -179.5, 89.5, 1.0)
}

#[test]
fn halos_across_the_antimeridian_are_the_other_side_exactly() {
    let region = globe();
    let (level, halo) = (14, 40);
    let (_, cols) = region.tiles.tiles_on_level(level);
    let n = region.tiles.samples() as usize;
    let row = region.tiles.tile_containing(0.0, 45.0, level).row;
    let west =
        cem::compute(&region, &region.tiles.tile_samples(TileId::new(level, row, 0), halo), &Layer::ALL).expect("west");
    let east = cem::compute(&region, &region.tiles.tile_samples(TileId::new(level, row, cols - 1), 0), &Layer::ALL)
        .expect("east");
    for layer in [Layer::Dem, Layer::Cover, Layer::Canopy, Layer::Cem, Layer::Max4, Layer::Max32] {
        let (Some(Samples::Float(w)), Some(Samples::Float(e))) = (west.samples(layer), east.samples(layer)) else {
            panic!()
        };
        no_nan(w, layer.name());
        let halo_part = w.crop(Window::new(0, halo as i64, halo + 1, n), f32::NAN);
        let other_side = e.crop(Window::new((n - 1 - halo) as i64, 0, halo + 1, n), f32::NAN);
        assert_same(&halo_part, &other_side, layer.name());
    }
    assert!(west.canopy.expect("canopy").data().iter().any(|&c| c > 1.0), "forest reaches across");
}

#[test]
fn halos_across_the_poles_read_the_opposite_meridian() {
    let region = globe();
    let (level, halo) = (10, 16);
    let (rows, cols) = region.tiles.tiles_on_level(level);
    for (row, sign) in [(rows - 1, 1i64), (0, -1)] {
        let a = cem::compute(&region, &region.tiles.tile_samples(TileId::new(level, row, 3), halo), &Layer::ALL)
            .expect("a");
        no_nan(a.max32.as_ref().expect("max32"), "max32");
        let b =
            cem::compute(&region, &region.tiles.tile_samples(TileId::new(level, row, 3 + cols / 2), halo), &Layer::ALL)
                .expect("b");
        let n = region.tiles.samples() as i64;
        // The pole is row `halo` (north) or `halo + n - 1` (south).
        let pole = if sign > 0 { halo as i64 } else { halo as i64 + n - 1 };
        // Safety zones are left out of the comparison: a zone reaching the pole
        // row holds that row's samples of its own meridians, and a lat/lon
        // lattice has one pole sample per meridian (all the same point, with
        // each meridian's value), so mirrored zones see different pole samples.
        for layer in [Layer::Dem, Layer::Cover, Layer::Canopy, Layer::Cem] {
            let (Some(Samples::Float(ra)), Some(Samples::Float(rb))) = (a.samples(layer), b.samples(layer)) else {
                panic!()
            };
            no_nan(ra, layer.name());
            for k in 1..=halo as i64 {
                let (beyond, inside) = ((pole - sign * k) as usize, (pole + sign * k) as usize);
                for x in 0..ra.width() {
                    assert_eq!(
                        ra.get(x, beyond).to_bits(),
                        rb.get(x, inside).to_bits(),
                        "{} row {beyond} x {x}",
                        layer.name()
                    );
                }
            }
        }
    }
}

#[test]
fn one_by_one_and_4097_squared_requests_and_refused_sizes() {
    let demo = common::demo();
    let one = produce::area(&demo, demo.bounds, 1, 1, Layer::Cem, Format::Bil32).expect("1x1");
    let v = f32::from_le_bytes(one.encoded.bytes[..4].try_into().expect("4 bytes"));
    assert!(one.encoded.bytes.len() == 4 && (300.0..4000.0).contains(&v), "{v}");
    let big = produce::area(&demo, demo.bounds, 4097, 4097, Layer::Cem, Format::Bil16).expect("4097²");
    assert_eq!(big.encoded.bytes.len(), 4097 * 4097 * 2);
    for (w, h) in [(0, 5), (5, 0), (9000, 10)] {
        let err = produce::area(&demo, demo.bounds, w, h, Layer::Cem, Format::Bil16).expect_err("refused");
        assert!(matches!(err, ProduceError::Request(GridError::BadSize { .. })), "{err}");
        assert!(err.to_string().contains(&format!("{w}×{h}")), "{err}");
    }
    let err = produce::tile(&demo, TileId::new(3, 99, 0), 0, Layer::Cem, Format::Bil16).expect_err("no such tile");
    assert!(err.to_string().contains("does not exist"), "{err}");
}
