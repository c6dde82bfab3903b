//! A region: everything the pipeline reads, assembled and checked — the tile
//! grid, the DEM, the land-cover raster, the canopy proxy and the encodings.
//! Built from a configuration file ([`crate::config`]) or, with none, from the
//! embedded demo ([`crate::demo`]).

use crate::canopy::CanopyProxy;
use crate::encode::Quantization;
use crate::grid::{BBox, TileGrid};
use crate::raster::resample::Resampling;
use crate::source::{BlockCache, GeoRaster};
use std::sync::Arc;

/// A named forest type and its canopy proxy.
#[derive(Clone)]
pub struct Forest {
    /// The name in the configuration.
    pub name: String,
    /// Its proxy.
    pub proxy: Arc<dyn CanopyProxy>,
}

/// The sources and settings of one region.
#[derive(Clone)]
pub struct Region {
    /// Human-readable name.
    pub name: String,
    /// Changes with anything that changes a tile's bytes (the cache key).
    pub version: String,
    /// Tiles made from upstream servers' data expire after this long.
    pub upstream_ttl: Option<std::time::Duration>,
    /// The World Wind tiling.
    pub tiles: TileGrid,
    /// The area with data (the default box of whole-area builds).
    pub bounds: BBox,
    /// Ground elevation, metres.
    pub dem: GeoRaster,
    /// How the DEM is resampled.
    pub dem_resampling: Resampling,
    /// Derived land cover (band 0 cover, band 1 class), if any.
    pub landcover: Option<GeoRaster>,
    /// The RGB map the land cover was keyed from, if it was (for the relief
    /// preview's colours).
    pub map: Option<GeoRaster>,
    /// The canopy proxy of forest of no named type.
    pub proxy: Arc<dyn CanopyProxy>,
    /// Named forest types and their proxies; land-cover band `2 + k` is the
    /// cover of type `k` (`forests[k − 1]`, type 0 being `proxy`'s).
    pub forests: Vec<Forest>,
    /// 16-bit encodings of heights.
    pub heights_16: Quantization,
    /// The block cache every source of the region reads through.
    pub cache: Arc<BlockCache>,
}

/// What a tile client needs to know about a served region
/// (`/tiles.json`): its tiling, its bounds and the largest halo served.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Tileset {
    /// Region name.
    pub name: String,
    /// Level-0 tile delta, degrees.
    pub level0_delta_deg: f64,
    /// Samples per tile side.
    pub samples: u32,
    /// West, south, east, north, degrees.
    pub bounds: [f64; 4],
    /// Largest `?halo=` the server accepts.
    pub max_halo: usize,
}

impl Region {
    /// The region's tileset descriptor.
    pub fn tileset(&self, max_halo: usize) -> Tileset {
        let b = self.bounds;
        Tileset {
            name: self.name.clone(),
            level0_delta_deg: self.tiles.level0_delta_deg(),
            samples: self.tiles.samples(),
            bounds: [b.west, b.south, b.east, b.north],
            max_halo,
        }
    }

    /// The proxy of each forest type, type 0 (no name) first.
    pub fn proxies(&self) -> Vec<&dyn CanopyProxy> {
        std::iter::once(self.proxy.as_ref()).chain(self.forests.iter().map(|f| f.proxy.as_ref())).collect()
    }

    /// A multi-line summary for `sylva info`.
    pub fn describe(&self) -> String {
        let b = &self.bounds;
        let mut lines = vec![
            format!("region     {}", self.name),
            format!("bounds     W {:.6} S {:.6} E {:.6} N {:.6}", b.west, b.south, b.east, b.north),
            format!(
                "tiles      level-0 delta {}°, {} samples per side",
                self.tiles.level0_delta_deg(),
                self.tiles.samples()
            ),
            describe_raster("dem", &self.dem),
        ];
        if let Some(lc) = &self.landcover {
            lines.push(describe_raster("landcover", lc));
        } else {
            lines.push("landcover  none (no forest anywhere)".into());
        }
        lines.push(format!("canopy     {}", self.proxy.describe()));
        for f in &self.forests {
            lines.push(format!("forest     {}: {}", f.name, f.proxy.describe()));
        }
        lines.push(format!(
            "png16      heights h = {} + {} · v (v = 0 is nodata; cover and surface use every code)",
            self.heights_16.offset, self.heights_16.scale
        ));
        lines.join("\n")
    }
}

fn describe_raster(label: &str, r: &GeoRaster) -> String {
    let (w, h) = r.size();
    let g = r.georef();
    format!("{label:<10} {} — {w}×{h} px, {:?}, pixel {:.3} m", r.name().display(), g.crs, g.pixel_m())
}

impl std::fmt::Debug for Region {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Region({:?})", self.name)
    }
}
