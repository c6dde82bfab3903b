//! Canopy proxies: generic canopy height (metres above ground) anchored to the
//! world, multiplied by the cover map and added to the ground (dissertation
//! 6.3, "Canopy Proxy Models and Height Map Texture Creation").
//!
//! A proxy is evaluated on a whole sample grid at once so that it can choose
//! its own traversal; the value at a sample must depend only on the sample's
//! lattice coordinate and the grid's spacing (never on the grid's extent), so
//! tiles stay seamless.
//!
//! Two kinds: the built-in [`ProceduralProxy`] (one hashed tree per world
//! cell) and the [`TiledProxy`], Wang tiles made from a LiDAR canopy height
//! model (`sylva canopy`): [`chm`] rasterises a point cloud (with
//! [`outliers`] and [`ground`]), [`wang`] turns the CHM into a tile set
//! ([`quilt`] picks the pieces, [`blend`] joins them), [`frame`] lays tiles
//! over the globe.
//!
//! Invariant: nothing here reads or writes files (`source::las` reads point
//! clouds, `source::proxy` and `encode::geotiff` read and write tile sets).

pub mod blend;
pub mod chm;
pub mod frame;
pub mod grid;
pub mod ground;
pub mod outliers;
pub mod procedural;
pub mod quilt;
pub mod stats;
pub mod tiled;
pub mod tileset;
pub mod wang;

pub use procedural::{ProceduralProxy, ProxyParams};
pub use tiled::TiledProxy;
pub use tileset::{Layout, TileSet};

use crate::grid::SampleGrid;
use crate::raster::Raster;

/// Maximal runs `start..end` of the columns of row `r` (of `width`) where
/// `cover` is positive; the whole row without a cover.
pub fn covered_runs(cover: Option<&Raster<f32>>, r: usize, width: usize) -> Vec<(usize, usize)> {
    let Some(cover) = cover else { return vec![(0, width)] };
    let mut out: Vec<(usize, usize)> = Vec::new();
    for (c, _) in cover.row(r).iter().enumerate().filter(|(_, v)| **v > 0.0) {
        match out.last_mut() {
            Some(last) if last.1 == c => last.1 = c + 1,
            _ => out.push((c, c + 1)),
        }
    }
    out
}

/// A canopy height field over the globe.
pub trait CanopyProxy: Send + Sync {
    /// Canopy height above ground (m) at every sample of `grid` where
    /// `cover` (a raster the size of the grid) is positive, or at every
    /// sample without one; other samples are left at 0. The proxy is
    /// filtered to the grid's sample spacing.
    fn heights(&self, grid: &SampleGrid, cover: Option<&Raster<f32>>) -> Raster<f32>;

    /// True if the proxy is filtered the same way at both sample spacings
    /// (metres), so a sample shared by grids of both has one value. The
    /// default is the safe answer.
    fn alike_at(&self, _spacing_a_m: f64, _spacing_b_m: f64) -> bool {
        false
    }

    /// The largest height the proxy can return (m).
    fn max_height_m(&self) -> f32;

    /// A one-line description for `sylva info` and logs.
    fn describe(&self) -> String;
}
