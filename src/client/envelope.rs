//! Heights known before a flight: the few coarse tiles that cover the
//! region (the deepest level whose tiles are at least as large as the
//! region, so at most 2 × 2 of them), fetched once. They give any sector's
//! lowest ground and highest CEM ([`HeightEnvelope::range`]) for the static
//! bounds of [`super::tiletree::TileTree`].
//!
//! The coarse samples miss what lies between them, so a sector's range is
//! taken over its samples and one more on every side, and widened by the
//! largest step between neighbouring samples there (what a surface that
//! varies like its samples can hide between two of them). These bounds
//! steer refinement and cull the tiles to draw ([`super::cull`]) before
//! those are loaded; they are not proven — a peak sharper than the coarse
//! steps around it could rise above them — but hold on every tile of levels
//! 9 to 14 over the demo's summit, valley floor and middle (tested). Hulls
//! and ray casting use each tile's own data.

use super::source::{FetchError, TileSource};
use super::tile::{TilePayload, plausible};
use crate::grid::{BBox, Sector, TileGrid, TileId};

/// One coarse tile's samples (no halo), row 0 at the north.
struct Coarse {
    sector: Sector,
    samples: usize,
    ground: Vec<f32>,
    cem: Vec<f32>,
}

/// The coarse tiles over a region.
pub struct HeightEnvelope {
    tiles: Vec<Coarse>,
}

impl HeightEnvelope {
    /// Fetches the coarse tiles over `source`'s region.
    pub fn fetch(source: &dyn TileSource) -> Result<HeightEnvelope, FetchError> {
        let mut payloads = Vec::new();
        for id in covering(&source.grid(), &source.bounds()) {
            payloads.extend(source.fetch(id, 0)?);
        }
        Ok(HeightEnvelope::of(&source.grid(), &payloads))
    }

    /// The envelope of the coarse tiles `payloads` on `grid` (their halos
    /// left out; a payload of the wrong size, which no tile is prepared
    /// from, too; heights no tile holds are nodata, as in tiles).
    pub fn of<'a>(grid: &TileGrid, payloads: impl IntoIterator<Item = &'a TilePayload>) -> HeightEnvelope {
        let n = grid.samples() as usize;
        let whole = |p: &&TilePayload| [&p.dem, &p.cem].iter().all(|l| l.len() == (n + 2 * p.halo).pow(2));
        let tiles = payloads
            .into_iter()
            .filter(whole)
            .map(|p| {
                let size = n + 2 * p.halo;
                let inner = |layer: &[f32]| -> Vec<f32> {
                    (p.halo..p.halo + n)
                        .flat_map(|y| layer[y * size + p.halo..][..n].iter().map(|&v| plausible(v)))
                        .collect()
                };
                Coarse { sector: grid.sector(p.id), samples: n, ground: inner(&p.dem), cem: inner(&p.cem) }
            })
            .collect();
        HeightEnvelope { tiles }
    }

    /// The lowest ground and highest CEM over `sector`, widened (see the
    /// module doc); `None` where no coarse sample lies near it.
    pub fn range(&self, sector: &Sector) -> Option<(f64, f64)> {
        // A sector past ±180° meets tiles of the other side turned.
        let turns = sector.turns();
        let ranges = self.tiles.iter().flat_map(|t| turns.iter().filter_map(|s| t.range(s)));
        ranges.reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
    }
}

/// The tiles of the deepest level whose tiles are at least as large as
/// `bounds` that cover it (at most 2 × 2): every deeper tile over the region
/// lies in one of them.
pub fn covering(grid: &TileGrid, b: &BBox) -> Vec<TileId> {
    let extent = (b.east - b.west).max(b.north - b.south);
    let level = (0..30).take_while(|&l| grid.tile_delta_deg(l) >= extent).last().unwrap_or(0);
    grid.tiles_over(b, level)
}

impl Coarse {
    /// Sample indices `(x0..x1, y0..y1)` of `s` with one more on each side.
    fn window(&self, s: &Sector) -> Option<(std::ops::Range<usize>, std::ops::Range<usize>)> {
        let (t, n) = (&self.sector, self.samples as f64 - 1.0);
        let (step_x, step_y) = ((t.max_lon - t.min_lon) / n, (t.max_lat - t.min_lat) / n);
        let x0 = ((s.min_lon - t.min_lon) / step_x).floor() - 1.0;
        let x1 = ((s.max_lon - t.min_lon) / step_x).ceil() + 1.0;
        let y0 = ((t.max_lat - s.max_lat) / step_y).floor() - 1.0;
        let y1 = ((t.max_lat - s.min_lat) / step_y).ceil() + 1.0;
        let clamp = |v: f64| v.clamp(0.0, n) as usize;
        let (xs, ys) = (clamp(x0)..clamp(x1) + 1, clamp(y0)..clamp(y1) + 1);
        (x1 >= 0.0 && y1 >= 0.0 && x0 <= n && y0 <= n).then_some((xs, ys))
    }

    fn range(&self, s: &Sector) -> Option<(f64, f64)> {
        let (xs, ys) = self.window(s)?;
        let n = self.samples;
        let (mut lo, mut hi, mut step) = (f32::INFINITY, f32::NEG_INFINITY, 0.0f32);
        for y in ys.clone() {
            for x in xs.clone() {
                let (g, c) = (self.ground[y * n + x], self.cem[y * n + x]);
                lo = lo.min(g);
                hi = hi.max(c);
                for (dx, dy) in [(1, 0), (0, 1)] {
                    let (nx, ny) = (x + dx, y + dy);
                    if xs.contains(&nx) && ys.contains(&ny) {
                        step = step.max((self.ground[ny * n + nx] - g).abs()).max((self.cem[ny * n + nx] - c).abs());
                    }
                }
            }
        }
        // NaN (nodata) drops out of min, max and the steps.
        (lo <= hi).then(|| (f64::from(lo - step), f64::from(hi + step)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::source::RegionSource;
    use std::sync::Arc;

    #[test]
    fn the_demo_envelope_holds_finer_tiles_heights() {
        // The tiles of levels 9 to 14 over the demo's highest summit, its
        // deepest valley floor and its middle: the widened coarse samples
        // hold every finer sample, canopy included.
        let region = Arc::new(crate::config::load(None).unwrap());
        let source = RegionSource::new(region.clone());
        let envelope = HeightEnvelope::fetch(&source).unwrap();
        assert!(!envelope.tiles.is_empty() && envelope.tiles.len() <= 4);
        let b = region.bounds;
        let anchors: Vec<TilePayload> = envelope_tiles(&source);
        let place = |pick: fn(f32, f32) -> bool, layer: fn(&TilePayload) -> &Vec<f32>| {
            let (mut best, mut at) = (f32::NAN, (0.0, 0.0));
            for p in &anchors {
                let (s, n) = (region.tiles.sector(p.id), region.tiles.samples() as usize);
                for (k, &v) in layer(p).iter().enumerate() {
                    let (x, y) = ((k % n) as f64 / (n - 1) as f64, (k / n) as f64 / (n - 1) as f64);
                    let (lon, lat) = (s.min_lon + x * (s.max_lon - s.min_lon), s.max_lat - y * (s.max_lat - s.min_lat));
                    let inside = (b.west..=b.east).contains(&lon) && (b.south..=b.north).contains(&lat);
                    if inside && (best.is_nan() || pick(v, best)) {
                        (best, at) = (v, (lon, lat));
                    }
                }
            }
            at
        };
        let summit = place(|a, b| a > b, |p| &p.cem);
        let floor = place(|a, b| a < b, |p| &p.dem);
        let middle = (0.5 * (b.west + b.east), 0.5 * (b.south + b.north));
        let finite = |v: &Vec<f32>| v.iter().copied().filter(|h| h.is_finite()).map(f64::from).collect::<Vec<_>>();
        for (lon, lat) in [summit, floor, middle] {
            for level in 9..=14 {
                let id = region.tiles.tile_containing(lon, lat, level);
                let fine = source.fetch(id, 0).unwrap().unwrap();
                let (lo, hi) = envelope.range(&region.tiles.sector(id)).unwrap();
                let ground = finite(&fine.dem).into_iter().fold(f64::INFINITY, f64::min);
                let top = finite(&fine.cem).into_iter().fold(f64::NEG_INFINITY, f64::max);
                assert!(ground >= lo && top <= hi, "{id}: {ground}..{top} outside {lo}..{hi}");
                assert!(hi - lo < 3000.0, "{lo}..{hi} is a useful bound");
            }
        }
    }

    /// The coarse tiles of the envelope, as payloads without halo.
    fn envelope_tiles(source: &RegionSource) -> Vec<TilePayload> {
        covering(&source.grid(), &source.bounds()).into_iter().filter_map(|id| source.fetch(id, 0).unwrap()).collect()
    }

    #[test]
    fn implausible_heights_bound_nothing() {
        // Regression: one infinite sample made every range (−∞, ∞), and
        // every tile was culled.
        let grid = TileGrid::new(36.0, 33).unwrap();
        let id = TileId::new(3, 10, 20);
        let size = 33 + 2;
        let mut payload = crate::client::tile::tests::ramp(&grid, id, 1);
        payload.cem[5 * size + 7] = f32::INFINITY;
        payload.dem[6 * size + 7] = f32::MIN;
        let envelope = HeightEnvelope::of(&grid, [&payload]);
        let (lo, hi) = envelope.range(&grid.sector(id)).unwrap();
        assert!(lo > 900.0 && hi < 1200.0, "{lo}..{hi}");
    }

    #[test]
    fn heights_are_read_across_the_antimeridian() {
        // A coarse tile each side of 180°: 100 m west of it, 900 m east.
        let grid = TileGrid::new(36.0, 65).unwrap();
        let flat = |id: TileId, h: f32| {
            let n = grid.samples() as usize;
            Coarse { sector: grid.sector(id), samples: n, ground: vec![h; n * n], cem: vec![h; n * n] }
        };
        let (_, cols) = grid.tiles_on_level(0);
        let envelope =
            HeightEnvelope { tiles: vec![flat(TileId::new(0, 2, cols - 1), 100.0), flat(TileId::new(0, 2, 0), 900.0)] };
        let across = Sector { min_lat: -17.0, max_lat: -16.0, min_lon: 179.5, max_lon: 180.5 };
        assert_eq!(envelope.range(&across), Some((100.0, 900.0)), "both sides of the region");
        let west_of_it = Sector { min_lon: 170.0, max_lon: 171.0, ..across };
        assert_eq!(envelope.range(&west_of_it), Some((100.0, 100.0)));
    }

    #[test]
    fn a_region_across_the_antimeridian_is_covered_on_both_sides() {
        let grid = TileGrid::new(36.0, 513).unwrap();
        let across = BBox { west: 179.5, south: -16.5, east: 180.5, north: -16.0 };
        let tiles = covering(&grid, &across);
        let (_, cols) = grid.tiles_on_level(tiles[0].level);
        let mut columns: Vec<u64> = tiles.iter().map(|t| t.col).collect();
        columns.dedup();
        assert_eq!(columns, [0, cols - 1], "{tiles:?}");
        assert!(grid.tile_delta_deg(tiles[0].level) >= 1.0);
    }
}
