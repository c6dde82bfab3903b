//! The scene of `sylva bench lod`: a square of a region in a local metric
//! frame, its tile quadtree with relief bounds from the DEM, trees placed by
//! [`crate::lod::splats`] in the region's real cover, their object tree, and
//! a recorded flyover. Built once; the benchmark then times selection on it.

use crate::cem::{self, Layer};
use crate::lod::quadtree::TileQuadtree;
use crate::lod::splats::TreeField;
use crate::lod::split::{Item, ObjectTree};
use crate::raster::Raster;
use crate::region::Region;
use glam::{DVec2, DVec3};

/// Metres per degree of latitude.
const M_PER_DEG: f64 = 6_371_000.0 * std::f64::consts::PI / 180.0;

/// Cover and ground sampled on a square, `cell_m` apart.
pub struct Ground {
    /// Side of the square, metres.
    pub side_m: f64,
    cell_m: f64,
    cover: Raster<f32>,
    dem: Raster<f32>,
}

impl Ground {
    /// Samples the central square of `region` (at most `max_side_m`) every
    /// `cell_m` metres.
    pub fn sample(region: &Region, max_side_m: f64, cell_m: f64) -> Result<Ground, String> {
        let b = region.bounds;
        let lat0 = 0.5 * (b.south + b.north);
        let m_per_lon = M_PER_DEG * lat0.to_radians().cos();
        let side_m = ((b.east - b.west) * m_per_lon).min((b.north - b.south) * M_PER_DEG).min(max_side_m);
        let (cx, cy) = (0.5 * (b.west + b.east), lat0);
        let half = (0.5 * side_m / m_per_lon, 0.5 * side_m / M_PER_DEG);
        let square = crate::grid::BBox { west: cx - half.0, south: cy - half.1, east: cx + half.0, north: cy + half.1 };
        let n = (side_m / cell_m).ceil().clamp(2.0, 4096.0) as usize;
        let grid = square.area_grid(n, n).map_err(|e| e.to_string())?;
        let p = cem::compute(region, &grid, &[Layer::Cover, Layer::Dem]).map_err(|e| e.to_string())?;
        let (Some(cover), Some(dem)) = (p.cover, p.dem) else { return Err("no cover or DEM computed".into()) };
        Ok(Ground { side_m, cell_m: side_m / n as f64, cover, dem })
    }

    /// Nearest sample of `r` at `p` (metres from the south-west corner;
    /// rows run north to south).
    fn at(&self, r: &Raster<f32>, p: DVec2) -> f64 {
        let n = r.width() as f64;
        let x = (p.x / self.cell_m).floor().clamp(0.0, n - 1.0) as usize;
        let y = (n - 1.0 - (p.y / self.cell_m).floor()).clamp(0.0, n - 1.0) as usize;
        f64::from(r.get(x, y))
    }

    /// Vegetation cover at `p`.
    pub fn cover(&self, p: DVec2) -> f64 {
        if p.x < 0.0 || p.y < 0.0 || p.x >= self.side_m || p.y >= self.side_m {
            return 0.0;
        }
        let c = self.at(&self.cover, p);
        if c.is_finite() { c } else { 0.0 }
    }

    /// Ground height at `p`, metres (0 where there is no data).
    pub fn height(&self, p: DVec2) -> f64 {
        let h = self.at(&self.dem, p);
        if h.is_finite() { h } else { 0.0 }
    }

    /// Lowest and highest ground in a box (5 × 5 samples, widened by 20 m).
    pub fn relief(&self, lo: DVec2, hi: DVec2) -> (f64, f64) {
        let mut r = (f64::MAX, f64::MIN);
        for k in 0..25 {
            let t = DVec2::new(f64::from(k % 5) / 4.0, f64::from(k / 5) / 4.0);
            let h = self.height(lo + (hi - lo) * t);
            r = (r.0.min(h), r.1.max(h));
        }
        (r.0 - 20.0, r.1 + 20.0)
    }
}

/// Everything the benchmark selects over.
pub struct Scene {
    /// The region's name.
    pub name: String,
    /// Cover and ground.
    pub ground: Ground,
    /// Terrain tiles.
    pub tiles: TileQuadtree,
    /// Tree groups as the splitting hierarchy sees them.
    pub items: Vec<Item>,
    /// Their object quadtree.
    pub objects: ObjectTree,
    /// Trees in all.
    pub trees: u64,
    /// The tree field.
    pub field: TreeField,
}

impl Scene {
    /// Builds the scene: tiles down to about `leaf_m`, trees `spacing_m`
    /// apart at full cover.
    pub fn build(name: &str, ground: Ground, leaf_m: f64, spacing_m: f64) -> Scene {
        let depth = (ground.side_m / leaf_m).log2().ceil().clamp(1.0, 12.0) as u8;
        let relief = |lo: DVec2, hi: DVec2| ground.relief(lo, hi);
        // Root error: a tenth of the side; it halves per level.
        let tiles = TileQuadtree::square(DVec2::ZERO, ground.side_m, depth, ground.side_m / 10.0, &relief);
        let field = TreeField { spacing_m, seed: 7, splats_per_tree: 32 };
        let cover = |p: DVec2| ground.cover(p);
        let groups = field.groups_in(DVec2::ZERO, DVec2::splat(ground.side_m), &cover);
        let trees = groups.iter().map(|g| g.trees.len() as u64).sum();
        let items: Vec<Item> = groups
            .iter()
            .map(|g| {
                let c = (DVec2::new(g.block.0 as f64, g.block.1 as f64) + 0.5) * field.group_side_m();
                field.item(g, ground.height(c) + 15.0)
            })
            .collect();
        let objects = ObjectTree::build(&items);
        Scene { name: name.to_string(), ground, tiles, items, objects, trees, field }
    }

    /// A recorded flyover: `frames` eye positions on a closed loop over the
    /// square, 250–450 m above the ground, 4 m a frame (240 m/s at 60 Hz),
    /// looking ahead and down.
    pub fn flyover(&self, frames: usize) -> Vec<(DVec3, DVec3)> {
        let c = self.ground.side_m / 2.0;
        let radius = 0.3 * self.ground.side_m;
        let eye = |k: f64| {
            let a = k * 4.0 / radius;
            let p = DVec2::new(c + radius * a.cos(), c + 0.8 * radius * (a + 0.3 * (3.0 * a).sin()).sin());
            DVec3::new(p.x, p.y, self.ground.height(p) + 350.0 + 100.0 * (5.0 * a).sin())
        };
        (0..frames)
            .map(|k| {
                let (here, next) = (eye(k as f64), eye(k as f64 + 1.0));
                let ahead = (next - here).with_z(0.0).normalize_or(DVec3::X);
                (here, (ahead - DVec3::Z * 0.35).normalize())
            })
            .collect()
    }
}
