//! What the server makes: encoded products of a sample grid — a World Wind
//! tile, a tile of a quadtree set (XYZ or WMTS), a Cesium terrain tile, or a
//! WMS image — their cache keys, and how each is computed (synchronously, on
//! a worker).

use crate::cem::{self, Layer, LayerSamples, Stats};
use crate::encode::{self, EncodeError, Format, Samples};
use crate::grid::quad::TileSet;
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
    /// An RGBA PNG picture: the relief preview or the map colours.
    Rgba,
    /// A data layer drawn as an RGBA PNG picture ([`encode::data_picture`]):
    /// what a picture format (JPEG) answers for a data layer.
    Picture,
    /// Cesium's heightmap terrain ([`encode::heightmap`]).
    Heightmap,
}

impl Encoding {
    /// File extension in cache paths.
    pub fn extension(self) -> &'static str {
        match self {
            Encoding::Data(Format::Bil16) => "bil",
            Encoding::Data(Format::Bil32) => "bil32",
            Encoding::Data(Format::Png16) | Encoding::Terrarium | Encoding::Rgba => "png",
            Encoding::Data(Format::Tiff) => "tif",
            Encoding::Picture => "picture.png",
            Encoding::Heightmap => "terrain",
        }
    }

    /// MIME type.
    pub fn mime(self) -> &'static str {
        match self {
            Encoding::Data(f) => f.mime(),
            Encoding::Terrarium | Encoding::Rgba | Encoding::Picture => "image/png",
            Encoding::Heightmap => "application/octet-stream",
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
    /// A tile of 256² pixels in a quadtree set: an XYZ (Web Mercator) or a
    /// geographic WMTS tile.
    Quad {
        /// Layer.
        layer: MapLayer,
        /// The tile matrix set.
        set: TileSet,
        /// Zoom, column, row (from the north).
        zxy: (u32, u64, u64),
    },
    /// A Cesium terrain tile of heights.
    Terrain {
        /// Layer (heights).
        layer: Layer,
        /// Zoom, column, row (from the south).
        zxy: (u32, u64, u64),
    },
    /// A WMS image on its own grid (kept in memory, not in the cache).
    Image {
        /// Layer.
        layer: MapLayer,
        /// Pixel centres.
        grid: SampleGrid,
        /// Encoding.
        encoding: Encoding,
    },
}

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
            Product::Quad { layer, set, zxy: (z, x, y) } => {
                let dir = match set {
                    TileSet::WebMercator => "xyz",
                    TileSet::Crs84 => "crs84",
                };
                Some(format!("{version}/{dir}/{}/{z}/{x}/{y}.png", layer.name()))
            }
            Product::Terrain { layer, zxy: (z, x, y) } => {
                Some(format!("{version}/cesium/{}/{z}/{x}/{y}.terrain", layer.name()))
            }
            Product::Image { .. } => None,
        }
    }

    /// The key of the product in memory: its cache key or, for an image
    /// (kept in memory only), one naming its grid exactly, so that a retry
    /// after a timeout, or the same request at once, shares one computation.
    pub fn memory_key(&self, version: &str) -> String {
        match self {
            Product::Image { layer, grid, encoding } => {
                format!("{version}/image/{}/{encoding:?}/{grid:?}", layer.name())
            }
            _ => self.key(version).unwrap_or_default(),
        }
    }

    /// The layer.
    pub fn layer(&self) -> MapLayer {
        match self {
            Product::Tile { layer, .. } | Product::Quad { layer, .. } | Product::Image { layer, .. } => *layer,
            Product::Terrain { layer, .. } => MapLayer::Data(*layer),
        }
    }

    /// The encoding.
    pub fn encoding(&self) -> Encoding {
        match self {
            Product::Tile { encoding, .. } | Product::Image { encoding, .. } => *encoding,
            Product::Quad { layer, .. } if layer.is_picture() => Encoding::Rgba,
            Product::Quad { .. } => Encoding::Terrarium,
            Product::Terrain { .. } => Encoding::Heightmap,
        }
    }

    /// Whether the product lies off the region's data: empty (Cesium's: 0 m
    /// everywhere), and made at once again — not worth a cache entry, which
    /// any client could add without end.
    pub fn off_data(&self, region: &Region) -> bool {
        self.grid(region).is_ok_and(|g| !region.dem.may_cover(&g))
    }

    /// The sample grid, checked against the region's tiling.
    pub fn grid(&self, region: &Region) -> Result<SampleGrid, GridError> {
        match self {
            Product::Tile { id, halo, .. } => {
                region.tiles.check(*id)?;
                Ok(region.tiles.tile_samples(*id, *halo))
            }
            Product::Quad { set, zxy: (z, x, y), .. } => set.tile_grid(*z, *x, *y),
            Product::Terrain { zxy, .. } => super::cesium::tile_grid(region, *zxy),
            Product::Image { grid, .. } => Ok(*grid),
        }
    }
}

/// A computed product.
#[derive(Clone, Debug)]
pub struct Computed {
    /// The bytes; empty when the grid holds no data (an absent tile).
    pub bytes: Vec<u8>,
    /// Every sample alike (or no data), in an encoding that does not depend
    /// on the tile's position: the bytes are stored once for all such tiles.
    pub uniform: bool,
    /// Stage times.
    pub stats: Stats,
    /// Encoding time.
    pub encode: Duration,
}

impl Computed {
    /// "No data here".
    fn absent(stats: Stats) -> Computed {
        Computed { bytes: Vec::new(), uniform: true, stats, encode: Duration::ZERO }
    }
}

/// Computes a product. An empty result means "no data here".
pub fn compute(region: &Region, product: &Product) -> Result<Computed, ProduceError> {
    let grid = product.grid(region)?;
    if let Product::Terrain { layer, zxy } = product {
        return super::cesium::compute(region, *layer, *zxy, &grid);
    }
    match product.layer() {
        MapLayer::Relief if region.dem.may_cover(&grid) => relief(region, &grid),
        MapLayer::Relief => Ok(Computed::absent(Stats::default())),
        MapLayer::Colour => colour(region, &grid),
        MapLayer::Data(layer) if product.encoding() == Encoding::Picture => data_picture(region, &grid, layer),
        MapLayer::Data(layer) => {
            let (samples, stats) = samples(region, &grid, layer)?;
            encode_samples(region, &grid, layer, product.encoding(), samples.as_ref(), stats)
        }
    }
}

/// The samples of `layer` on `grid`, or `None` where the grid misses the
/// region's data (nothing is computed there).
pub fn samples(
    region: &Region,
    grid: &SampleGrid,
    layer: Layer,
) -> Result<(Option<LayerSamples>, Stats), ProduceError> {
    if !region.dem.may_cover(grid) {
        return Ok((None, Stats::default()));
    }
    let mut products = cem::compute(region, grid, &[layer])?;
    let samples =
        products.take(layer).ok_or_else(|| EncodeError(format!("layer {} was not computed", layer.name())))?;
    Ok((Some(samples), products.stats))
}

/// Encodes a layer's samples on `grid` (empty bytes for no data); `stats`
/// are the stage times that made them.
pub fn encode_samples(
    region: &Region,
    grid: &SampleGrid,
    layer: Layer,
    encoding: Encoding,
    samples: Option<&LayerSamples>,
    stats: Stats,
) -> Result<Computed, ProduceError> {
    let Some(samples) = samples.map(LayerSamples::view).filter(|s| !s.all_nodata()) else {
        return Ok(Computed::absent(stats));
    };
    let start = Instant::now();
    let bytes = match (encoding, samples) {
        (Encoding::Terrarium, Samples::Float(r)) => encode::terrarium::encode(r)?,
        (Encoding::Data(format), samples) => encode::encode(layer, samples, grid, format, region.heights_16)?.bytes,
        _ => return Err(EncodeError(format!("layer {} cannot be encoded as {encoding:?}", layer.name())).into()),
    };
    // GeoTIFFs carry their position; the other encodings only the samples.
    let uniform = encoding != Encoding::Data(Format::Tiff) && uniform(&samples);
    Ok(Computed { bytes, uniform, stats, encode: start.elapsed() })
}

/// Every sample the same (bitwise).
fn uniform(samples: &Samples) -> bool {
    fn same<T: Copy>(data: &[T], eq: impl Fn(T, T) -> bool) -> bool {
        data.first().is_none_or(|&a| data.iter().all(|&b| eq(a, b)))
    }
    match samples {
        Samples::Float(r) => same(r.data(), |a, b| a.to_bits() == b.to_bits()),
        Samples::Class(r) => same(r.data(), |a, b| a == b),
    }
}

/// The relief preview: the CEM with one sample of margin for shading.
fn relief(region: &Region, grid: &SampleGrid) -> Result<Computed, ProduceError> {
    let around = grid.grown(1);
    let products = cem::compute(region, &around, &[Layer::Cem, Layer::Surface])?;
    let (Some(cem), Some(surface)) = (&products.cem, &products.surface) else {
        return Err(EncodeError("relief needs the CEM and the surface".into()).into());
    };
    let inner = own_samples(grid);
    if cem.crop(inner, f32::NAN).all_nodata() {
        return Ok(Computed::absent(products.stats));
    }
    let map = crate::produce::map_colours(region, grid)?;
    let surface = surface.crop(inner, cem::surface::NODATA);
    let start = Instant::now();
    let spacing_m = row_spacings_m(grid);
    let relief = encode::relief::Relief { cem, surface: &surface, map: map.as_deref(), spacing_m: &spacing_m };
    let bytes = encode::relief::encode(&relief)?;
    Ok(Computed { bytes, uniform: false, stats: products.stats, encode: start.elapsed() })
}

/// A data layer drawn as a picture: its samples with one of margin, for
/// shading.
fn data_picture(region: &Region, grid: &SampleGrid, layer: Layer) -> Result<Computed, ProduceError> {
    let (samples, stats) = samples(region, &grid.grown(1), layer)?;
    let Some(samples) = samples.filter(|s| !within_margin(s, grid).view().all_nodata()) else {
        return Ok(Computed::absent(stats));
    };
    let start = Instant::now();
    let bytes = encode::data_picture::encode(layer, &samples, &row_spacings_m(grid))?;
    Ok(Computed { bytes, uniform: false, stats, encode: start.elapsed() })
}

/// Where the samples of `grid` lie within samples computed with a margin of
/// one.
fn own_samples(grid: &SampleGrid) -> Window {
    Window::new(1, 1, grid.width(), grid.height())
}

/// The samples of `grid` within samples computed with a margin of one
/// (a picture with no data of its own is absent, whatever its margin holds).
fn within_margin(samples: &LayerSamples, grid: &SampleGrid) -> LayerSamples {
    let inner = own_samples(grid);
    match samples {
        LayerSamples::Float(r) => LayerSamples::Float(r.crop(inner, f32::NAN)),
        LayerSamples::Class(r) => LayerSamples::Class(r.crop(inner, cem::surface::NODATA)),
    }
}

/// Ground distance between columns and between rows at each row of `grid`,
/// metres. Both are the row's own, not the grid's middle's (the east–west
/// distance shrinks with the cosine of the row's latitude; a Web Mercator
/// row's height in degrees shrinks with it too): tiles that share a row
/// shade it with bitwise the same spacing, so north–south neighbours agree.
fn row_spacings_m(grid: &SampleGrid) -> Vec<(f64, f64)> {
    let dx = grid.lon.step_deg();
    let m = crate::geo::METRES_PER_DEGREE;
    (0..grid.height()).map(|y| (dx * grid.lat.coord(y).to_radians().cos() * m, grid.lat.step_deg_at(y) * m)).collect()
}

/// The unshaded map colours.
fn colour(region: &Region, grid: &SampleGrid) -> Result<Computed, ProduceError> {
    let products = cem::compute(region, grid, &[Layer::Surface])?;
    let Some(surface) = products.surface.filter(|s| s.data().iter().any(|&c| c != cem::surface::NODATA)) else {
        return Ok(Computed::absent(products.stats));
    };
    let map = crate::produce::map_colours(region, grid)?;
    let start = Instant::now();
    let bytes = encode::relief::encode_colours(&surface, map.as_deref())?;
    Ok(Computed { bytes, uniform: false, stats: products.stats, encode: start.elapsed() })
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
        let h = Product::Tile { layer: MapLayer::Relief, id: TileId::new(9, 1, 2), halo: 32, encoding: Encoding::Rgba };
        assert_eq!(h.key("v1").as_deref(), Some("v1/relief/9/1/1_2_h32.png"));
        let x = Product::Quad { layer: MapLayer::Data(Layer::Dem), set: TileSet::WebMercator, zxy: (11, 400, 780) };
        assert_eq!(x.key("v2").as_deref(), Some("v2/xyz/dem/11/400/780.png"));
        let g = Product::Quad { layer: MapLayer::Relief, set: TileSet::Crs84, zxy: (11, 4000, 780) };
        assert_eq!(g.key("v2").as_deref(), Some("v2/crs84/relief/11/4000/780.png"));
    }
}
