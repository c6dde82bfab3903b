//! A canopy proxy made of Wang tiles ([`TileSet`], e.g. built from LiDAR by
//! `sylva canopy`), laid over the globe (dissertation 6.3: the "generic,
//! tileable patch of canopy height data", non-repeating with Wang tiles).
//!
//! The world frame ([`super::frame`]) cuts each zone into square cells of
//! one tile; every cell edge gets a colour by a hash of the edge, every cell
//! the tile whose edge colours match (and a hashed variant), so neighbouring
//! cells continue each other and the arrangement never repeats.
//!
//! Filtering to the sample spacing `s`: texels are read bilinearly from mip
//! level `log₂(s / texel)` of the tiles, linearly between the two nearest
//! levels (trilinear); past the last level (one texel per tile) the canopy
//! fades to its mean over one more octave, as the procedural proxy does.
//!
//! Invariant: the height at a sample is a function of the sample's
//! longitude, latitude and the grid spacing only.

use super::CanopyProxy;
use super::blend::blend;
use super::frame::{Position, Zone};
use super::tileset::{Edges, TileSet};
use crate::geo::METRES_PER_DEGREE;
use crate::grid::SampleGrid;
use crate::noise::hash2;
use crate::raster::{Raster, Window};

/// A tile-set canopy proxy.
pub struct TiledProxy {
    name: String,
    set: TileSet,
    frame: Zone,
    seed: u64,
}

/// Which edge a hash is for.
const HORIZONTAL: u64 = 0x4852;
const VERTICAL: u64 = 0x5652;
const VARIANT: u64 = 0x5641;

impl TiledProxy {
    /// The proxy of a tile set, named for messages (its file); `seed`
    /// decorrelates proxies of different forest types.
    pub fn new(name: impl Into<String>, set: TileSet, seed: u64) -> TiledProxy {
        // Zones blend over two tiles on either side of their edge.
        let frame = Zone { blend_m: 2.0 * set.layout().tile_m() };
        TiledProxy { name: name.into(), set, frame, seed }
    }

    /// The tile set.
    pub fn set(&self) -> &TileSet {
        &self.set
    }

    /// The tile of cell `(ci, cj)` of `zone` (`cj` counts rows southwards).
    fn tile(&self, zone: i64, ci: i64, cj: i64) -> usize {
        let l = self.set.layout();
        let colour =
            |a: i64, b: i64, kind: u64| (hash2(a, b, hash2(zone, kind as i64, self.seed)) % l.colours as u64) as usize;
        let variant = (hash2(ci, cj, hash2(zone, VARIANT as i64, self.seed)) % l.variants as u64) as usize;
        l.index(Edges {
            n: colour(ci, cj, HORIZONTAL),
            s: colour(ci, cj + 1, HORIZONTAL),
            w: colour(ci, cj, VERTICAL),
            e: colour(ci + 1, cj, VERTICAL),
            variant,
        })
    }

    /// The texture of `cols × rows` cells of one zone at mip level `k`, as
    /// the hash lays the tiles out (for previews and checks).
    pub fn mosaic(&self, cols: usize, rows: usize, k: usize) -> Raster<f32> {
        let t = self.set.layout().tile_px >> k.min(self.set.levels() - 1);
        let mut out = Raster::filled(cols * t, rows * t, 0.0);
        for cj in 0..rows {
            for ci in 0..cols {
                let tile = self.set.level(k.min(self.set.levels() - 1), self.tile(0, ci as i64, cj as i64));
                out.paste(tile, Window::new(0, 0, t, t), ci * t, cj * t);
            }
        }
        out
    }

    /// Level `k`, bilinear, at a position.
    fn bilinear(&self, k: usize, p: &Position) -> f32 {
        let texel_m = self.set.layout().cell_m * (1u64 << k) as f64;
        let t = (self.set.layout().tile_px >> k) as i64;
        // Texel centres at half-integers; rows count southwards.
        let (s, r) = (p.x_m / texel_m - 0.5, -p.y_m / texel_m - 0.5);
        let (i0, j0) = (s.floor() as i64, r.floor() as i64);
        let (fx, fy) = ((s - i0 as f64) as f32, (r - j0 as f64) as f32);
        let texel = |i: i64, j: i64| {
            let tile = self.tile(p.zone, i.div_euclid(t), j.div_euclid(t));
            self.set.level(k, tile).get(i.rem_euclid(t) as usize, j.rem_euclid(t) as usize)
        };
        let top = texel(i0, j0) + fx * (texel(i0 + 1, j0) - texel(i0, j0));
        let bottom = texel(i0, j0 + 1) + fx * (texel(i0 + 1, j0 + 1) - texel(i0, j0 + 1));
        top + fy * (bottom - top)
    }

    /// Level `k`, or the mean past the last level.
    fn level(&self, k: usize, p: &Position) -> f32 {
        if k < self.set.levels() { self.bilinear(k, p) } else { self.set.stats().mean }
    }

    /// The height at `p` filtered to a spacing of `spacing_m`.
    fn filtered(&self, p: &Position, spacing_m: f64) -> f32 {
        let lod = (spacing_m / self.set.layout().cell_m).log2().max(0.0);
        let k = lod.floor() as usize;
        let t = (lod - k as f64) as f32;
        let fine = self.level(k, p);
        if t == 0.0 { fine } else { fine + t * (self.level(k + 1, p) - fine) }
    }

    /// The height at `(lon, lat)` for samples `spacing_m` apart.
    pub fn height(&self, lon_deg: f64, lat_deg: f64, spacing_m: f64) -> f32 {
        let [(w, own), (v, other)] = self.frame.locate(lon_deg, lat_deg);
        let own_h = self.filtered(&own, spacing_m);
        if v == 0.0 {
            return own_h;
        }
        blend(&[(w, own_h), (v, self.filtered(&other, spacing_m))], self.set.stats().mean)
    }
}

impl CanopyProxy for TiledProxy {
    fn heights(&self, grid: &SampleGrid, cover: Option<&Raster<f32>>) -> Raster<f32> {
        use rayon::prelude::*;
        let mut out = Raster::filled(grid.width(), grid.height(), 0.0f32);
        let spacing_m = grid.lat.step_deg() * METRES_PER_DEGREE;
        let globe = grid.globe();
        let width = grid.width().max(1);
        out.data_mut().par_chunks_mut(width).enumerate().for_each(|(r, row)| {
            for (start, end) in super::covered_runs(cover, r, row.len()) {
                for (c, v) in row.iter_mut().enumerate().take(end).skip(start) {
                    let (lon, lat) = globe.at(c as i64, r as i64);
                    *v = self.height(lon, lat, spacing_m);
                }
            }
        });
        out
    }

    fn max_height_m(&self) -> f32 {
        self.set.stats().max
    }

    fn describe(&self) -> String {
        let l = self.set.layout();
        format!(
            "tiles {}: {} Wang tiles of {}² texels at {:.2} m ({:.0} m), {} colours, {} variants; heights {}",
            self.name,
            l.count(),
            l.tile_px,
            l.cell_m,
            l.tile_m(),
            l.colours,
            l.variants,
            self.set.stats()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::canopy::tileset::Layout;
    use crate::grid::{BBox, TileGrid};

    /// Tiles whose texels say which tile they are (16 × tile + texel row).
    fn labelled() -> TiledProxy {
        let layout = Layout { tile_px: 16, colours: 2, variants: 1, cell_m: 1.0 };
        let tiles = (0..16).map(|i| Raster::from_fn(16, 16, |_, y| (16 * i + y) as f32)).collect();
        TiledProxy::new("test", TileSet::new(layout, tiles).unwrap(), 7)
    }

    #[test]
    fn neighbouring_cells_get_tiles_whose_edges_match() {
        let p = labelled();
        let l = *p.set.layout();
        for (ci, cj) in [(0, 0), (5, -3), (-7, 11), (100, 100)] {
            let here = l.edges(p.tile(3, ci, cj));
            assert_eq!(here.e, l.edges(p.tile(3, ci + 1, cj)).w);
            assert_eq!(here.s, l.edges(p.tile(3, ci, cj + 1)).n);
        }
        // Both colours and all tiles occur.
        let used: std::collections::HashSet<usize> = (0..400).map(|i| p.tile(3, i % 20, i / 20)).collect();
        assert_eq!(used.len(), 16);
    }

    #[test]
    fn coarse_grids_see_the_mean_and_fine_ones_texels() {
        let p = labelled();
        let tiles = TileGrid::new(36.0, 513).unwrap();
        let coarse = BBox::parse("10,46,10.1,46.1").unwrap().point_grid(9, 9, &tiles).unwrap();
        let east = Raster::from_fn(9, 9, |x, _| if x > 0 { 1.0 } else { 0.0 });
        let h = p.heights(&coarse, Some(&east));
        assert!(h.data().iter().enumerate().all(|(i, &v)| if i % 9 == 0 { v == 0.0 } else { v == p.set.stats().mean }));
        // 0.25 m spacing: bilinear between texels, within the texel range.
        let fine = BBox::parse("10,46,10.00002,46.00002").unwrap().point_grid(9, 9, &tiles).unwrap();
        let h = p.heights(&fine, None);
        assert!(h.data().iter().all(|&v| (0.0..=255.0).contains(&v)));
    }
}
