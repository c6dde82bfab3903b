//! `sylva canopy`: LiDAR point clouds → canopy height model → Wang tile set
//! (dissertation 6.6: the canopy proxy "derived from a LIDAR scan ...
//! converted to an elevation map with 0.5m resolution and afterwards ...
//! converted into a large, tileable texture", here without the manual step).
//!
//! Reads the clouds through `source::las`, does the work in `canopy`
//! (pure), and encodes GeoTIFFs through `encode::geotiff`; writing files is
//! the caller's. Also used by the configuration, which may name point clouds
//! as a forest type's proxy.

use crate::canopy::chm::{self, Chm, ChmError, ChmOptions};
use crate::canopy::grid::MetricGrid;
use crate::canopy::wang::{self, WangError, WangParams};
use crate::canopy::{TileSet, TiledProxy};
use crate::encode::{EncodeError, geotiff, relief};
use crate::raster::{Raster, Window};
use crate::source::{SourceError, las};
use std::path::PathBuf;
use thiserror::Error;

/// What to build from which clouds.
#[derive(Clone, Debug)]
pub struct Options {
    /// LAS/LAZ files, read as one cloud.
    pub files: Vec<PathBuf>,
    /// CHM cell side, metres.
    pub cell_m: f64,
    /// EPSG code replacing the files' CRS.
    pub crs: Option<u32>,
    /// The CHM's grid (default: the cells of `cell_m` covering the cloud).
    pub grid: Option<MetricGrid>,
    /// Texels per tile side (default: [`WangParams::tile_px_for`] the CHM).
    pub tile_px: Option<usize>,
    /// Colours per tile edge.
    pub colours: usize,
    /// Tiles per colour combination.
    pub variants: usize,
}

/// The canopy height model's cell side unless one is given, metres (6.3.2:
/// "an elevation map with 0.5m resolution").
pub const DEFAULT_CELL_M: f64 = 0.5;

impl Options {
    /// Defaults for these files at this resolution.
    pub fn new(files: Vec<PathBuf>, cell_m: f64) -> Options {
        Options { files, cell_m, crs: None, grid: None, tile_px: None, colours: 2, variants: 2 }
    }
}

/// Why no proxy was built; every variant names the clouds.
#[derive(Debug, Error)]
pub enum LidarError {
    /// A file could not be read.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// The cloud gives no canopy height model.
    #[error("{name}: {source}")]
    Chm {
        /// The files.
        name: String,
        /// Why.
        source: ChmError,
    },
    /// The CHM gives no tile set.
    #[error("{name}: {source}")]
    Wang {
        /// The files.
        name: String,
        /// Why.
        source: WangError,
    },
    /// A GeoTIFF could not be encoded.
    #[error(transparent)]
    Encode(#[from] EncodeError),
}

/// Pits deeper than this below their neighbours' median are filled before
/// a CHM becomes tiles: 2 m is below the height of a crown's shoulder over
/// its neighbour at 0.5 m, far above LiDAR's 15 cm noise.
pub const PIT_M: f32 = 2.0;

/// A CHM made from clouds.
#[derive(Clone, Debug)]
pub struct Model {
    /// The files, for messages.
    pub name: String,
    /// Their CRS.
    pub epsg: u32,
    /// Points read.
    pub points: usize,
    /// The canopy height model.
    pub chm: Chm,
}

/// The CHM of the clouds.
pub fn model(options: &Options) -> Result<Model, LidarError> {
    let cloud = las::read(&options.files, options.crs)?;
    let name = cloud.name();
    let chm_options = ChmOptions { cell_m: options.cell_m, ..ChmOptions::default() };
    let chm = chm::build(&cloud, options.grid, &chm_options)
        .map_err(|source| LidarError::Chm { name: name.clone(), source })?;
    Ok(Model { name, epsg: cloud.epsg, points: cloud.len(), chm })
}

/// `r` averaged over blocks of `2^level` cells (NaN where a block has no data).
fn box_reduce(r: &Raster<f32>, level: usize) -> Raster<f32> {
    let f = 1usize << level;
    Raster::from_fn(r.width() / f, r.height() / f, |x, y| {
        let cells = (0..f * f).map(|i| r.get(x * f + i % f, y * f + i / f)).filter(|v| !v.is_nan());
        let (sum, n) = cells.fold((0.0, 0), |(s, n), v| (s + v, n + 1));
        if n == 0 { f32::NAN } else { sum / n as f32 }
    })
}

/// The CHM and the tile set made from it.
pub fn build(options: &Options) -> Result<(Model, TileSet), LidarError> {
    let model = model(options)?;
    let (g, heights) = (&model.chm.grid, &model.chm.heights);
    let tile_px =
        options.tile_px.unwrap_or_else(|| WangParams::tile_px_for(g.cell_m, heights.width(), heights.height()));
    let params = WangParams::new(tile_px, options.colours, options.variants);
    let smooth = chm::fill_pits(heights, PIT_M);
    let target = crate::canopy::stats::sorted(heights.data().iter().copied());
    let set = wang::build(&smooth, &target, g.cell_m, &params)
        .map_err(|source| LidarError::Wang { name: model.name.clone(), source })?;
    Ok((model, set))
}

/// A proxy for the CEM from clouds (a configuration's `lidar = [...]`).
pub fn proxy(options: &Options, seed: u64) -> Result<TiledProxy, LidarError> {
    let (model, set) = build(options)?;
    Ok(TiledProxy::new(model.name, set, seed))
}

impl Model {
    /// The CHM as a GeoTIFF on its grid (nodata −32768 outside the scan).
    pub fn chm_tiff(&self) -> Result<Vec<u8>, EncodeError> {
        geotiff::write_metric(&self.chm.heights, &self.chm.grid, self.epsg, None)
    }

    /// The tile set's atlas as a GeoTIFF, its layout in the description; it
    /// is placed at the CHM's north-west corner (a texture has no place of
    /// its own; there it opens over the forest it came from).
    pub fn proxy_tiff(&self, set: &TileSet) -> Result<Vec<u8>, EncodeError> {
        let atlas = set.atlas();
        let grid = MetricGrid { width: atlas.width(), height: atlas.height(), ..self.chm.grid };
        geotiff::write_metric(&atlas, &grid, self.epsg, Some(&set.layout().tag()))
    }

    /// A picture for people: the CHM (left) beside the proxy's tiles as the
    /// hash lays them out over `cells × cells` cells (right), both a square
    /// of `cells` tiles at mip level `level` (each level halves the pixels),
    /// shaded grey.
    pub fn preview_png(&self, set: &TileSet, cells: usize, level: usize) -> Result<Vec<u8>, EncodeError> {
        let mosaic = TiledProxy::new("", set.clone(), 0).mosaic(cells, cells, level);
        let side = mosaic.width();
        let chm = box_reduce(&self.chm.heights, level);
        // The middle of the CHM, as large as the mosaic (NaN beyond a small CHM).
        let at = |n: usize| (n as i64 - side as i64) / 2;
        let chm = chm.crop(Window::new(at(chm.width()), at(chm.height()), side, side), f32::NAN);
        let gap = 6;
        let mut both = Raster::filled(2 * side + gap, side, f32::NAN);
        both.paste(&chm, Window::new(0, 0, side, side), 0, 0);
        both.paste(&mosaic, Window::new(0, 0, side, side), side + gap, 0);
        let max = set.stats().max.max(1.0);
        relief::grey(
            &both.crop(Window::new(-1, -1, both.width() + 2, side + 2), f32::NAN),
            self.chm.grid.cell_m * (1 << level) as f64,
            max,
        )
    }

    /// What was made, for people.
    pub fn report(&self, set: &TileSet) -> String {
        let counted = |n: usize, noun: &str| if n == 1 { format!("1 {noun}") } else { format!("{n} {noun}s") };
        let c = &self.chm;
        let g = &c.grid;
        let heights =
            if c.normalised { "heights as given (normalised)" } else { "heights above the ground TIN of class 2" };
        let l = set.layout();
        [
            format!("cloud   {}: {} points, EPSG:{}, {heights}", self.name, self.points, self.epsg),
            format!(
                "noise   {} in noise classes, {} isolated, {} outside the ground model",
                c.dropped.noise_class, c.dropped.isolated, c.off_ground
            ),
            format!(
                "chm     {}×{} cells of {} m, {} voids filled; {}",
                g.width,
                g.height,
                g.cell_m,
                c.filled,
                crate::canopy::stats::HeightStats::of(c.heights.data().iter().copied())
            ),
            format!(
                "proxy   {} of {}² texels ({:.0} m), {}, {}; {}",
                counted(l.count(), "Wang tile"),
                l.tile_px,
                l.tile_m(),
                counted(l.colours, "colour"),
                counted(l.variants, "variant"),
                set.stats()
            ),
        ]
        .into_iter()
        .chain(c.mostly_filled().map(|coarser| {
            format!(
                "warning most cells had no point and were filled: a resolution of {coarser:.2} m or coarser gives about one point per cell"
            )
        }))
        .chain(c.heights.data().iter().all(|&h| h.is_nan() || h <= 0.0).then(|| {
            "warning no cell stands above the ground: the proxy is flat (is the cloud ground only, or its classes wrong?)"
                .to_string()
        }))
        .collect::<Vec<_>>()
        .join("\n")
    }
}
