//! Preview images of the demo region for eyes (ignored tests writing PNGs to
//! the temporary directory).

use super::dem::{COLS, DemSource, ROWS};
use crate::source::PixelSource;

fn dem_heights() -> Vec<f32> {
    let dem = DemSource::new().unwrap();
    let mut out = vec![0f32; COLS * ROWS];
    for by in 0..ROWS.div_ceil(256) {
        for bx in 0..COLS.div_ceil(256) {
            let b = dem.read_block(bx, by).unwrap().remove(0);
            for r in 0..b.height() {
                for c in 0..b.width() {
                    out[(by * 256 + r) * COLS + bx * 256 + c] = b.get(c, r);
                }
            }
        }
    }
    out
}

/// Hillshade (sun from the north-west, 45° up) tinted by elevation.
fn hillshade(h: &[f32], w: usize, ht: usize, dx_m: f64, dy_m: f64) -> image::RgbImage {
    let mut img = image::RgbImage::new(w as u32, ht as u32);
    let (lx, ly, lz) = (-0.5f64, 0.5f64, std::f64::consts::FRAC_1_SQRT_2);
    for y in 0..ht {
        for x in 0..w {
            let at = |xx: usize, yy: usize| h[yy.min(ht - 1) * w + xx.min(w - 1)] as f64;
            let gx = (at(x + 1, y) - at(x.saturating_sub(1), y)) / (2.0 * dx_m);
            let gy = (at(x, y.saturating_sub(1)) - at(x, y + 1)) / (2.0 * dy_m);
            let n = (gx * gx + gy * gy + 1.0).sqrt();
            let shade = ((-gx * lx - gy * ly + lz) / n).clamp(0.0, 1.0);
            let e = ((at(x, y) - 850.0) / 2100.0).clamp(0.0, 1.0);
            let (r, g, b) = if at(x, y) == 900.0 {
                (120.0, 170.0, 230.0)
            } else {
                (90.0 + 150.0 * e, 150.0 + 80.0 * e, 90.0 + 150.0 * e)
            };
            let s = 0.35 + 0.65 * shade;
            img.put_pixel(x as u32, y as u32, image::Rgb([(r * s) as u8, (g * s) as u8, (b * s) as u8]));
        }
    }
    img
}

#[test]
#[ignore = "writes preview PNGs for eyes"]
fn write_dem_preview() {
    let h = dem_heights();
    let (lo, hi) = h.iter().fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    println!("DEM {COLS}×{ROWS}, {lo:.1}–{hi:.1} m");
    let img = hillshade(&h, COLS, ROWS, 1.0 / 3600.0 * crate::geo::METRES_PER_DEGREE * 0.69, 30.9);
    img.save(std::env::temp_dir().join("demo_dem.png")).unwrap();
}

fn map_image(x0: usize, y0: usize, w: usize, h: usize, step: usize) -> image::RgbImage {
    let map = super::map::MapSource::new().unwrap();
    let blocks = crate::source::Blocks::new(std::sync::Arc::new(map), &crate::source::BlockCache::new(1 << 30));
    let px = blocks.read(crate::raster::Window::new(x0 as i64, y0 as i64, w * step, h * step)).unwrap();
    image::RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let (sx, sy) = (x as usize * step, y as usize * step);
        image::Rgb([0, 1, 2].map(|b| px[b].get(sx, sy) as u8))
    })
}

#[test]
#[ignore = "writes preview PNGs for eyes"]
fn write_map_preview() {
    let start = std::time::Instant::now();
    map_image(0, 0, 1050, 950, 2).save(std::env::temp_dir().join("demo_map.png")).unwrap();
    println!("whole sheet (every 2nd pixel) in {:?}", start.elapsed());
    map_image(900, 700, 400, 300, 1).save(std::env::temp_dir().join("demo_map_crop.png")).unwrap();
    map_image(300, 150, 400, 300, 1).save(std::env::temp_dir().join("demo_map_rock.png")).unwrap();
    map_image(450, 1000, 400, 300, 1).save(std::env::temp_dir().join("demo_map_lake.png")).unwrap();
}

#[test]
#[ignore = "timings for the report"]
fn time_demo() {
    use std::time::Instant;
    let t = Instant::now();
    let mut acc = 0.0;
    for i in 0..2_000 {
        acc +=
            super::terrain::ground(-9_000.0 + (i % 100) as f64 * 180.0, -8_000.0 + (i / 100) as f64 * 800.0).height_m;
    }
    println!("ground(), one point alone: {:.1} µs per call ({acc:.0})", t.elapsed().as_nanos() as f64 / 2e6);
    let dem = DemSource::new().unwrap();
    let t = Instant::now();
    for by in 0..ROWS.div_ceil(256) {
        for bx in 0..COLS.div_ceil(256) {
            dem.read_block(bx, by).unwrap();
        }
    }
    println!("whole DEM ({COLS}×{ROWS}), one thread: {:?}", t.elapsed());
    let map = super::map::MapSource::new().unwrap();
    let mut times = Vec::new();
    for (bx, by) in [(0, 0), (2, 3), (4, 4), (6, 1), (7, 6), (3, 5), (1, 2), (5, 5), (2, 6), (6, 3)] {
        let t = Instant::now();
        map.read_block(bx, by).unwrap();
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    println!("map 256² blocks, one thread: {times:.1?} ms");
}
