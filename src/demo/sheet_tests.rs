//! Whole-sheet tests of the demo map: it reads like a topographic map, the
//! forest is crossed by lines that the close bridges, and blocks are
//! deterministic and seamless. The sheet is rendered once and shared.

use super::map::{COLS, MapSource, ROWS};
use super::palette;
use crate::raster::Raster;
use crate::raster::morphology::{MorphOp, apply_sequence};
use crate::source::{BlockCache, Blocks, PixelSource};
use std::sync::{Arc, OnceLock};

/// Palette indices (into `palette::ALL`).
const FOREST: u8 = 0;
const WATER: u8 = 2;
const SHORE: u8 = 3;
const CONTOUR: u8 = 4;
const PATH: u8 = 5;
const ROCK: u8 = 6;
const SCREE: u8 = 7;

/// The whole sheet read through the block cache, as palette indices.
fn sheet() -> &'static Raster<u8> {
    static SHEET: OnceLock<Raster<u8>> = OnceLock::new();
    SHEET.get_or_init(|| {
        let map: Arc<dyn PixelSource> = Arc::new(MapSource::new().unwrap());
        let blocks = Blocks::new(map, &BlockCache::new(1 << 30));
        let px = blocks.read(crate::raster::Window::new(0, 0, COLS, ROWS)).unwrap();
        Raster::from_fn(COLS, ROWS, |x, y| classify([px[0].get(x, y), px[1].get(x, y), px[2].get(x, y)]))
    })
}

/// The palette entry within the scanner noise (±3) of a colour.
fn classify(rgb: [f32; 3]) -> u8 {
    let hit = palette::ALL.iter().position(|(_, c)| (0..3).all(|k| (rgb[k] - f32::from(c[k])).abs() <= 3.0));
    hit.map_or(u8::MAX, |i| i as u8)
}

fn share(sheet: &Raster<u8>, classes: &[u8]) -> f64 {
    sheet.data().iter().filter(|c| classes.contains(c)).count() as f64 / sheet.data().len() as f64
}

#[test]
fn the_sheet_reads_like_a_topographic_map() {
    let s = sheet();
    assert!(s.data().iter().all(|&c| c != u8::MAX), "a pixel is off the palette");
    let shares: Vec<String> =
        palette::ALL.iter().enumerate().map(|(i, (name, _))| format!("{name} {:.4}", share(s, &[i as u8]))).collect();
    println!("{}", shares.join(", "));
    for (i, (name, _)) in palette::ALL.iter().enumerate() {
        assert!(share(s, &[i as u8]) > 0.0005, "{name} is missing");
    }
    let forest = share(s, &[FOREST]);
    let water = share(s, &[WATER, SHORE]);
    let rock = share(s, &[ROCK, SCREE]);
    assert!((0.25..0.50).contains(&forest), "forest {forest}");
    assert!((0.015..0.06).contains(&water), "water {water}");
    assert!((0.03..0.25).contains(&rock), "rock {rock}");
    assert!((0.08..0.40).contains(&share(s, &[CONTOUR])) && share(s, &[PATH]) > 0.002);
}

/// Line pixels (contours, paths) whose 5 × 5 neighbourhood is otherwise all
/// forest: lines cutting through the forest.
fn lines_inside_forest(s: &Raster<u8>) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for y in 2..ROWS - 2 {
        for x in 2..COLS - 2 {
            if !matches!(s.get(x, y), CONTOUR | PATH) {
                continue;
            }
            let mut forest = 0;
            let mut other = false;
            for yy in y - 2..=y + 2 {
                for xx in x - 2..=x + 2 {
                    match s.get(xx, yy) {
                        FOREST => forest += 1,
                        CONTOUR | PATH => {}
                        _ => other = true,
                    }
                }
            }
            if !other && forest >= 8 {
                out.push((x, y));
            }
        }
    }
    out
}

#[test]
fn the_close_bridges_the_lines_that_cross_forest() {
    let s = sheet();
    let mask = s.map(|c| if c == FOREST { 1.0f32 } else { 0.0 });
    let ops = MorphOp::parse_sequence("DDEE").unwrap();
    let closed = apply_sequence(&mask, &ops, 1);
    let lines = lines_inside_forest(s);
    let bridged = lines.iter().filter(|&&(x, y)| closed.get(x, y) == 1.0).count();
    let before = share(s, &[FOREST]);
    let after = closed.data().iter().filter(|&&v| v == 1.0).count() as f64 / (COLS * ROWS) as f64;
    println!("{bridged} of {} line pixels inside forest bridged; forest {before:.3} → {after:.3}", lines.len());
    // Lines really do cut the forest: a tenth of a percent of the sheet at least.
    assert!(lines.len() > COLS * ROWS / 1000, "{}", lines.len());
    assert!(bridged as f64 > 0.95 * lines.len() as f64, "{bridged} of {}", lines.len());
    assert!(after > before + 0.03, "the close adds the line pixels back to the forest");
}

#[test]
fn blocks_are_deterministic_and_windows_seamless() {
    let map = MapSource::new().unwrap();
    let a = map.read_block(3, 2).unwrap();
    assert_eq!(a, map.read_block(3, 2).unwrap());
    // A window shifted off the block grid agrees with the blocks it overlaps.
    let shifted = map.render(3 * 256 - 37, 2 * 256 - 101, 256, 256);
    for y in 0..155 {
        for x in 0..219 {
            for b in 0..3 {
                assert_eq!(shifted[b].get(37 + x, 101 + y), a[b].get(x, y), "({x}, {y}) band {b}");
            }
        }
    }
    // The same through the cache, across four blocks.
    let blocks = Blocks::new(Arc::new(MapSource::new().unwrap()), &BlockCache::new(1 << 28));
    let window = blocks.read(crate::raster::Window::new(3 * 256 - 7, 2 * 256 - 5, 20, 10)).unwrap();
    for b in 0..3 {
        assert_eq!(window[b].get(7, 5), a[b].get(0, 0));
        assert_eq!(window[b].get(19, 9), a[b].get(12, 4));
    }
}

#[test]
fn the_sheet_covers_the_dem_and_the_region() {
    let g = MapSource::new().unwrap().georef();
    let utm = crate::source::Crs::from_epsg(32632).unwrap();
    for (lon, lat) in [(9.995, 46.295), (10.255, 46.295), (9.995, 46.455), (10.255, 46.455)] {
        let (e, n) = utm.from_lon_lat(lon, lat).unwrap();
        let (px, py) = ((e - g.x0) / g.dx, (n - g.y0) / g.dy);
        assert!(px > 0.0 && py > 0.0 && px < COLS as f64 - 1.0 && py < ROWS as f64 - 1.0, "{lon} {lat}: {px} {py}");
    }
}
