//! The CEM pipeline: one function, [`compute`], that reads like Figure 6.1 of
//! the dissertation — (a) vegetation cover, (b) elevation resampling, (c) the
//! combined elevation map, (d) ray-casting acceleration data — plus the
//! surface-type channel.
//!
//! Invariants:
//! - **Seamless.** Every layer at a sample is a function of the sample's
//!   lattice coordinate and the grid spacing only, or (safety zones) of such
//!   values within a fixed radius, computed with that margin. A tile therefore
//!   equals the same window of a whole-area build, and neighbours agree on
//!   shared samples.
//! - **Conservative.** Safety zones and the mipmap never lie below the surface
//!   they cover ([`accel`]).
//! - **Lazy.** Only the stages the requested layers need run (the elevation
//!   for every layer: no layer has data where the ground has none); a grid
//!   without ground data stops after the elevation stage, and a grid without
//!   forest skips cover resampling and the canopy ([`Stats`] counts the runs).
//! - No I/O beyond the sources, no async, no GPU.

pub mod accel;
pub mod colorkey;
pub mod combine;
pub mod landcover;
pub mod stats;
pub mod surface;

pub use stats::{Stage, Stats};

use crate::grid::SampleGrid;
use crate::raster::resample::Resampling;
use crate::raster::{Raster, Window};
use crate::region::Region;
use crate::source::SourceError;
use crate::source::georaster::Footprint;

/// The layers a tile can carry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Layer {
    /// Ground elevation, metres.
    Dem,
    /// Vegetation cover in [0, 1].
    Cover,
    /// Vegetation height above ground (proxy × cover), metres.
    Canopy,
    /// Combined elevation map: ground + canopy, metres.
    Cem,
    /// Surface class ids.
    Surface,
    /// Near safety zone: max CEM within 4 samples.
    Max4,
    /// Far safety zone: max CEM within 32 samples.
    Max32,
}

impl Layer {
    /// Every layer.
    pub const ALL: [Layer; 7] =
        [Layer::Dem, Layer::Cover, Layer::Canopy, Layer::Cem, Layer::Surface, Layer::Max4, Layer::Max32];

    /// The layer's name in requests and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Layer::Dem => "dem",
            Layer::Cover => "cover",
            Layer::Canopy => "canopy",
            Layer::Cem => "cem",
            Layer::Surface => "surface",
            Layer::Max4 => "max4",
            Layer::Max32 => "max32",
        }
    }

    /// The layer with this name.
    pub fn parse(text: &str) -> Option<Layer> {
        Layer::ALL.into_iter().find(|l| l.name().eq_ignore_ascii_case(text))
    }
}

/// The pipeline's output over one grid. Layers that were not asked for are
/// `None`.
#[derive(Clone, Debug, Default)]
pub struct Products {
    /// Ground elevation.
    pub dem: Option<Raster<f32>>,
    /// Cover.
    pub cover: Option<Raster<f32>>,
    /// Canopy height above ground.
    pub canopy: Option<Raster<f32>>,
    /// Ground + canopy.
    pub cem: Option<Raster<f32>>,
    /// Surface classes.
    pub surface: Option<Raster<u8>>,
    /// Near safety zone.
    pub max4: Option<Raster<f32>>,
    /// Far safety zone.
    pub max32: Option<Raster<f32>>,
    /// What ran and how long it took.
    pub stats: Stats,
}

impl Products {
    /// The samples of one layer, if computed.
    pub fn samples(&self, layer: Layer) -> Option<crate::encode::Samples<'_>> {
        use crate::encode::Samples::{Class, Float};
        match layer {
            Layer::Dem => self.dem.as_ref().map(Float),
            Layer::Cover => self.cover.as_ref().map(Float),
            Layer::Canopy => self.canopy.as_ref().map(Float),
            Layer::Cem => self.cem.as_ref().map(Float),
            Layer::Surface => self.surface.as_ref().map(Class),
            Layer::Max4 => self.max4.as_ref().map(Float),
            Layer::Max32 => self.max32.as_ref().map(Float),
        }
    }
}

/// One layer's samples, owned.
#[derive(Clone, Debug)]
pub enum LayerSamples {
    /// Continuous values, NaN = nodata.
    Float(Raster<f32>),
    /// Class ids.
    Class(Raster<u8>),
}

impl LayerSamples {
    /// The samples as the encoders take them.
    pub fn view(&self) -> crate::encode::Samples<'_> {
        match self {
            LayerSamples::Float(r) => crate::encode::Samples::Float(r),
            LayerSamples::Class(r) => crate::encode::Samples::Class(r),
        }
    }
}

impl Products {
    /// Moves one layer's samples out, if computed.
    pub fn take(&mut self, layer: Layer) -> Option<LayerSamples> {
        use LayerSamples::{Class, Float};
        match layer {
            Layer::Dem => self.dem.take().map(Float),
            Layer::Cover => self.cover.take().map(Float),
            Layer::Canopy => self.canopy.take().map(Float),
            Layer::Cem => self.cem.take().map(Float),
            Layer::Surface => self.surface.take().map(Class),
            Layer::Max4 => self.max4.take().map(Float),
            Layer::Max32 => self.max32.take().map(Float),
        }
    }
}

/// Which stages the requested layers need.
#[derive(Clone, Copy, Debug)]
struct Needs {
    cover: bool,
    canopy: bool,
    cem: bool,
    surface: bool,
    near: bool,
    far: bool,
}

impl Needs {
    fn of(layers: &[Layer]) -> Needs {
        let has = |l: Layer| layers.contains(&l);
        let (near, far) = (has(Layer::Max4), has(Layer::Max32));
        let cem = near || far || has(Layer::Cem);
        let canopy = cem || has(Layer::Canopy);
        let surface = has(Layer::Surface);
        Needs { cover: canopy || surface || has(Layer::Cover), canopy, cem, surface, near, far }
    }
}

/// True if `layer` has one value at a sample that `fine` and `coarse` (two
/// tile grids of nested lattices) share, so that a coarse tile equals its
/// four children decimated, bit for bit: every stage the layer needs reads
/// its sources alike on both grids. Neighbourhood layers (the safety zones,
/// in samples) never qualify.
pub fn alike_across(region: &Region, layer: Layer, fine: &SampleGrid, coarse: &SampleGrid) -> bool {
    let need = Needs::of(&[layer]);
    let metres = |g: &SampleGrid| g.lat.step_deg() * crate::geo::METRES_PER_DEGREE;
    !(need.near || need.far)
        && region.dem.samples_alike(fine, coarse)
        && (!need.cover || region.landcover.as_ref().is_none_or(|l| l.samples_alike(fine, coarse)))
        && (!need.canopy || region.landcover.is_none() || region.proxy.alike_at(metres(fine), metres(coarse)))
}

/// Runs the pipeline for `layers` on `grid`.
pub fn compute(region: &Region, grid: &SampleGrid, layers: &[Layer]) -> Result<Products, SourceError> {
    let need = Needs::of(layers);
    let mut stats = Stats::default();
    // The safety zones look up to 32 samples beyond the grid.
    let margin = accel::margin(need.near, need.far);
    let work = grid.grown(margin);

    // (b) Elevation data resampling: every layer needs it, since the region
    // is where the ground is (no cover or canopy without it).
    let ground = stats.time(Stage::Elevation, || region.dem.sample(&work, 0, region.dem_resampling))?;
    let no_ground = ground.all_nodata();

    // (a) Identification of arboreous regions: the cover map on the grid.
    let landcover = match need.cover && !no_ground {
        true => read_landcover(region, &work, &need, &mut stats)?,
        false => None,
    };
    let has_forest = landcover.as_ref().is_some_and(|f| f.bands[0].data().iter().any(|&c| c > 0.0));
    let cover = match &landcover {
        Some(f) if has_forest => Some(stats.time(Stage::Cover, || f.resample(0, Resampling::Bilinear))),
        _ => None,
    };

    // (c) Height map texture: canopy proxy × cover, added to the ground.
    let canopy = match (&cover, &landcover) {
        (Some(c), Some(f)) if need.canopy => Some(stats.time(Stage::Canopy, || canopy(region, &work, c, f))),
        _ => None,
    };
    let cem = match (&canopy, need.cem) {
        (Some(c), true) => Some(stats.time(Stage::Combine, || combine::cem(&ground, c))),
        (None, true) => Some(ground.clone()),
        _ => None,
    };
    let surface = (need.surface && !no_ground)
        .then(|| stats.time(Stage::Surface, || surface(&ground, cover.as_ref(), landcover.as_ref())));

    // (d) Ray casting acceleration data.
    let (near, far) = match &cem {
        Some(cem) if (need.near || need.far) && !no_ground => {
            stats.time(Stage::Zones, || accel::safety_zones(cem, need.near, need.far))
        }
        _ => (None, None),
    };

    let stages = Stages { ground, cover, canopy, cem, surface, near, far };
    Ok(stages.products(grid, margin, layers, stats))
}

/// The land cover's bands on `work`: cover, then the classes (for the
/// surface layer), then each forest type's cover (for typed canopies).
fn read_landcover(
    region: &Region,
    work: &SampleGrid,
    need: &Needs,
    stats: &mut Stats,
) -> Result<Option<Footprint>, SourceError> {
    let Some(lc) = &region.landcover else { return Ok(None) };
    let bands = if typed(region, need) {
        3 + region.forests.len()
    } else if need.surface {
        2
    } else {
        1
    };
    stats.time(Stage::Landcover, || lc.read(work, Resampling::Bilinear, bands))
}

/// Whether the canopy reads the cover of each forest type (bands 2 ..).
fn typed(region: &Region, need: &Needs) -> bool {
    need.canopy && !region.forests.is_empty()
}

/// Canopy heights over `work`: the proxy (or each forest type's) × cover.
fn canopy(region: &Region, work: &SampleGrid, cover: &Raster<f32>, landcover: &Footprint) -> Raster<f32> {
    match region.forests.is_empty() {
        true => combine::canopy(region.proxy.as_ref(), work, cover),
        false => combine::canopy_by_type(&region.proxies(), work, |k| landcover.resample(2 + k, Resampling::Bilinear)),
    }
}

/// Surface classes: the nearest land-cover class, forest where cover ≥ ½,
/// none off the ground.
fn surface(ground: &Raster<f32>, cover: Option<&Raster<f32>>, landcover: Option<&Footprint>) -> Raster<u8> {
    let classes = landcover.map(|f| f.resample(1, Resampling::Nearest));
    Raster::par_from_fn(ground.width(), ground.height(), |x, y| {
        let class = classes.as_ref().map_or(f32::NAN, |c| c.get(x, y));
        let c = cover.map_or(0.0, |c| c.get(x, y));
        surface::classify(class, c, !ground.get(x, y).is_nan())
    })
}

/// Every stage's raster over the grown grid, `None` where it did not run.
struct Stages {
    ground: Raster<f32>,
    cover: Option<Raster<f32>>,
    canopy: Option<Raster<f32>>,
    cem: Option<Raster<f32>>,
    surface: Option<Raster<u8>>,
    near: Option<Raster<f32>>,
    far: Option<Raster<f32>>,
}

impl Stages {
    /// The requested `layers` cropped to `grid` (the work grid less
    /// `margin`). Cover and canopy (0 where no forest was computed) have no
    /// data where the ground has none.
    fn products(self, grid: &SampleGrid, margin: usize, layers: &[Layer], stats: Stats) -> Products {
        let Stages { ground, cover, canopy, cem, surface, near, far } = self;
        let inner = Window::new(margin as i64, margin as i64, grid.width(), grid.height());
        let crop = |r: &Raster<f32>| r.crop(inner, f32::NAN);
        let on_ground = |r: Option<&Raster<f32>>| match r {
            Some(r) => crop(&r.zip_map(&ground, |v, g| if g.is_nan() { f32::NAN } else { v })),
            None => crop(&ground.map(|g| if g.is_nan() { f32::NAN } else { 0.0 })),
        };
        let nodata_out = || Raster::filled(grid.width(), grid.height(), f32::NAN);
        let no_surface = || Raster::filled(grid.width(), grid.height(), surface::NODATA);
        let wants = |l: Layer| layers.contains(&l);
        Products {
            dem: wants(Layer::Dem).then(|| crop(&ground)),
            cover: wants(Layer::Cover).then(|| on_ground(cover.as_ref())),
            canopy: wants(Layer::Canopy).then(|| on_ground(canopy.as_ref())),
            cem: cem.as_ref().filter(|_| wants(Layer::Cem)).map(crop),
            surface: wants(Layer::Surface).then(|| surface.map_or_else(no_surface, |s| s.crop(inner, surface::NODATA))),
            max4: wants(Layer::Max4).then(|| near.unwrap_or_else(nodata_out)),
            max32: wants(Layer::Max32).then(|| far.unwrap_or_else(nodata_out)),
            stats,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layer_names_round_trip() {
        for l in Layer::ALL {
            assert_eq!(Layer::parse(l.name()), Some(l));
        }
        assert_eq!(Layer::parse("CEM"), Some(Layer::Cem));
        assert_eq!(Layer::parse("relief"), None);
    }

    #[test]
    fn needs_follow_layer_dependencies() {
        let n = Needs::of(&[Layer::Max32]);
        assert!(n.cover && n.canopy && n.cem && n.far && !n.near && !n.surface);
        let d = Needs::of(&[Layer::Dem]);
        assert!(!d.cover && !d.canopy && !d.cem);
        let c = Needs::of(&[Layer::Cover]);
        assert!(c.cover && !c.canopy);
    }
}
