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

/// A canopy height field over the globe.
pub trait CanopyProxy: Send + Sync {
    /// Canopy height above ground (m) at every sample of `grid` where `wanted`
    /// is true; other samples are left at 0. The proxy is filtered to the
    /// grid's sample spacing.
    fn heights(&self, grid: &SampleGrid, wanted: &(dyn Fn(usize, usize) -> bool + Sync)) -> Raster<f32>;

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
