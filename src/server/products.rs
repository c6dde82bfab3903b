//! What the server makes: encoded products of a sample grid — a World Wind
//! tile, an XYZ tile, or a WMS image — their cache keys, and how each is
//! computed (synchronously, on a worker).

use crate::cem::{self, Layer, Stats};
use crate::encode::{self, EncodeError, Format, Samples};
use crate::grid::mercator::MercatorBox;
use crate::grid::{GridError, SampleGrid, TileId};
use crate::produce::ProduceError;
use crate::raster::Window;
use crate::region::Region;
use std::time::{Duration, Instant};

use super::wms::request::MapLayer;

/// How a product is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Encoding {
    /// One of the data formats.
    Data(Format),
    /// Terrarium RGB PNG (XYZ tiles).
    Terrarium,
    /// The RGBA relief preview.
    Relief,
}

impl Encoding {
    /// File extension in cache paths.
    pub fn extension(self) -> &'static str {
        match self {
            Encoding::Data(Format::Bil16) => "bil",
            Encoding::Data(Format::Bil32) => "bil32",
            Encoding::Data(Format::Png16) | Encoding::Terrarium | Encoding::Relief => "png",
            Encoding::Data(Format::Tiff) => "tif",
        }
    }

    /// MIME type.
    pub fn mime(self) -> &'static str {
        match self {
            Encoding::Data(f) => f.mime(),
            Encoding::Terrarium | Encoding::Relief => "image/png",
        }
    }
}

/// A product request.
#[derive(Clone, Debug, PartialEq)]
pub enum Product {
    /// A World Wind tile.
    Tile {
        /// Layer.
        layer: MapLayer,
        /// Address.
        id: TileId,
        /// Extra samples per side.
        halo: usize,
        /// Encoding.
        encoding: Encoding,
    },
    /// An XYZ Web Mercator tile of 256² pixels.
    Xyz {
        /// Layer.
        layer: MapLayer,
        /// Zoom, column, row.
        zxy: (u32, u64, u64),
    },
    /// A WMS image on its own grid (not cached).
    Image {
        /// Layer.
        layer: MapLayer,
        /// Pixel centres.
        grid: SampleGrid,
        /// Encoding.
        encoding: Encoding,
    },
}

/// Side of XYZ tiles, pixels.
pub const XYZ_SIDE: usize = 256;

impl Product {
    /// The cache key under `version`, or `None` for products not cached.
    pub fn key(&self, version: &str) -> Option<String> {
        match self {
            Product::Tile { layer, id, halo, encoding } => {
                let h = if *halo > 0 { format!("_h{halo}") } else { String::new() };
                let name = layer.name();
                let ext = encoding.extension();
                Some(format!("{version}/{name}/{}/{}/{}_{}{h}.{ext}", id.level, id.row, id.row, id.col))
            }
            Product::Xyz { layer, zxy: (z, x, y) } => Some(format!("{version}/xyz/{}/{z}/{x}/{y}.png", layer.name())),
            Product::Image { .. } => None,
        }
    }

    fn layer(&self) -> MapLayer {
        match self {
            Product::Tile { layer, .. } | Product::Xyz { layer, .. } | Product::Image { layer, .. } => *layer,
        }
    }

    fn encoding(&self) -> Encoding {
        match self {
            Product::Tile { encoding, .. } | Product::Image { encoding, .. } => *encoding,
            Product::Xyz { layer: MapLayer::Relief, .. } => Encoding::Relief,
            Product::Xyz { .. } => Encoding::Terrarium,
        }
    }

    /// The sample grid, checked against the region's tiling.
    pub fn grid(&self, region: &Region) -> Result<SampleGrid, GridError> {
        match self {
            Product::Tile { id, halo, .. } => {
                region.tiles.check(*id)?;
                Ok(region.tiles.tile_samples(*id, *halo))
            }
            Product::Xyz { zxy: (z, x, y), .. } => MercatorBox::of_tile(*z, *x, *y)?.area_grid(XYZ_SIDE, XYZ_SIDE),
            Product::Image { grid, .. } => Ok(*grid),
        }
    }
}

/// A computed product.
#[derive(Clone, Debug)]
pub struct Computed {
    /// The bytes; empty when the grid holds no data (an absent tile).
    pub bytes: Vec<u8>,
    /// Stage times.
    pub stats: Stats,
    /// Encoding time.
    pub encode: Duration,
}

/// Computes a product. An empty result means "no data here".
pub fn compute(region: &Region, product: &Product) -> Result<Computed, ProduceError> {
    let grid = product.grid(region)?;
    if !region.dem.may_cover(&grid) {
        return Ok(Computed { bytes: Vec::new(), stats: Stats::default(), encode: Duration::ZERO });
    }
    match product.layer() {
        MapLayer::Relief => relief(region, &grid),
        MapLayer::Data(layer) => data(region, &grid, layer, product.encoding()),
    }
}

fn data(region: &Region, grid: &SampleGrid, layer: Layer, encoding: Encoding) -> Result<Computed, ProduceError> {
    let products = cem::compute(region, grid, &[layer])?;
    let samples =
        products.samples(layer).ok_or_else(|| EncodeError(format!("layer {} was not computed", layer.name())))?;
    if no_data(&samples) {
        return Ok(Computed { bytes: Vec::new(), stats: products.stats, encode: Duration::ZERO });
    }
    let start = Instant::now();
    let bytes = match (encoding, samples) {
        (Encoding::Terrarium, Samples::Float(r)) => encode::terrarium::encode(r)?,
        (Encoding::Data(format), samples) => encode::encode(layer, samples, grid, format, region.heights_16)?.bytes,
        _ => return Err(EncodeError(format!("layer {} cannot be encoded as {encoding:?}", layer.name())).into()),
    };
    Ok(Computed { bytes, stats: products.stats, encode: start.elapsed() })
}

fn no_data(samples: &Samples) -> bool {
    match samples {
        Samples::Float(r) => r.all_nodata(),
        Samples::Class(r) => r.data().iter().all(|&c| c == cem::surface::NODATA),
    }
}

/// The relief preview: the CEM with one sample of margin for shading.
fn relief(region: &Region, grid: &SampleGrid) -> Result<Computed, ProduceError> {
    let around = grid.grown(1);
    let products = cem::compute(region, &around, &[Layer::Cem, Layer::Surface])?;
    let (Some(cem), Some(surface)) = (&products.cem, &products.surface) else {
        return Err(EncodeError("relief needs the CEM and the surface".into()).into());
    };
    if cem.all_nodata() {
        return Ok(Computed { bytes: Vec::new(), stats: products.stats, encode: Duration::ZERO });
    }
    let map = region.map.as_ref().map(|m| map_colours(m, grid)).transpose()?.flatten();
    let inner = Window::new(1, 1, grid.width(), grid.height());
    let surface = surface.crop(inner, cem::surface::NODATA);
    let start = Instant::now();
    let (dx, dy) = (grid.lon.step_deg(), grid.lat.step_deg());
    let mid_lat = grid.lat.coord_at((grid.height() as f64 - 1.0) / 2.0).to_radians();
    let spacing_m = (dx * mid_lat.cos() * crate::geo::METRES_PER_DEGREE, dy * crate::geo::METRES_PER_DEGREE);
    let bytes =
        encode::relief::encode(&encode::relief::Relief { cem, surface: &surface, map: map.as_deref(), spacing_m })?;
    Ok(Computed { bytes, stats: products.stats, encode: start.elapsed() })
}

/// The map's R, G, B at the grid's samples, read and projected once for the
/// three bands; `None` where the grid misses the map.
fn map_colours(
    map: &crate::source::GeoRaster,
    grid: &SampleGrid,
) -> Result<Option<Vec<crate::raster::Raster<f32>>>, ProduceError> {
    let bilinear = crate::raster::resample::Resampling::Bilinear;
    let footprint = map.read(grid, bilinear, 3)?;
    Ok(footprint.map(|f| (0..3).map(|b| f.resample(b, bilinear)).collect()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_follow_the_world_wind_layout_under_the_version() {
        let t = Product::Tile {
            layer: MapLayer::Data(Layer::Cem),
            id: TileId::new(9, 1939, 2704),
            halo: 0,
            encoding: Encoding::Data(Format::Bil16),
        };
        assert_eq!(t.key("v1").as_deref(), Some("v1/cem/9/1939/1939_2704.bil"));
        let h =
            Product::Tile { layer: MapLayer::Relief, id: TileId::new(9, 1, 2), halo: 32, encoding: Encoding::Relief };
        assert_eq!(h.key("v1").as_deref(), Some("v1/relief/9/1/1_2_h32.png"));
        let x = Product::Xyz { layer: MapLayer::Data(Layer::Dem), zxy: (11, 400, 780) };
        assert_eq!(x.key("v2").as_deref(), Some("v2/xyz/dem/11/400/780.png"));
    }
}
