//! The commands that make files from a region: `tile`, `build`, `canopy`
//! and `info`.

use anyhow::Result;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use sylva::canopy::Layout;
use sylva::cem::Layer;
use sylva::encode::Format;
use sylva::grid::{BBox, TileId};
use sylva::interrupt::Abandon;
use sylva::outputs;
use sylva::produce::{self, Product};
use sylva::region::Region;

/// What `tile` and `build` share: the region, the layer, its encoding and
/// the file.
#[derive(clap::Args)]
struct ProductArgs {
    /// Region configuration (default: the embedded demo region).
    #[arg(long)]
    config: Option<PathBuf>,
    /// dem, cover, canopy, cem, surface, max4 or max32.
    #[arg(long, value_parser = layer)]
    layer: Layer,
    /// bil16, bil32, png16 or tiff.
    #[arg(long, default_value = "tiff", value_parser = format)]
    format: Format,
    /// Output file.
    #[arg(short, long)]
    output: PathBuf,
}

impl ProductArgs {
    /// Loads the region, makes the product and writes it (refused before
    /// any work if the output would overwrite the configuration or a file
    /// it names).
    fn make(&self, product: impl FnOnce(&Region, Layer, Format) -> Result<Product>) -> Result<()> {
        let abandon = Abandon::watch();
        let inputs = sylva::config::input_files(self.config.as_deref())?;
        outputs::check(&inputs.iter().map(PathBuf::as_path).collect::<Vec<_>>(), &[&self.output])?;
        let region = sylva::config::load(self.config.as_deref())?;
        let product = product(&region, self.layer, self.format)?;
        abandon.writing(|| write(&self.output, &product))
    }
}

/// `sylva tile`.
#[derive(clap::Args)]
pub struct TileArgs {
    #[command(flatten)]
    product: ProductArgs,
    /// Tile level (0 = coarsest).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=i64::from(sylva::grid::TileGrid::MAX_LEVEL)))]
    level: u32,
    /// Tile row, counted from the south pole.
    #[arg(long)]
    row: u64,
    /// Tile column, counted from −180°.
    #[arg(long)]
    col: u64,
    /// Extra samples per side taken from the neighbours.
    #[arg(long, default_value_t = 0, value_parser = count_in(0..=sylva::produce::MAX_HALO))]
    halo: usize,
}

impl TileArgs {
    pub fn run(self) -> Result<()> {
        let id = TileId::new(self.level, self.row, self.col);
        self.product.make(|region, layer, format| {
            region.tiles.check(id).map_err(super::usage)?;
            let what = format!("tile {}/{}/{}", id.level, id.row, id.col);
            in_region(region, &region.tiles.sector(id).bbox(), &what)?;
            Ok(produce::tile(region, id, self.halo, layer, format)?)
        })
    }
}

/// `sylva build`.
#[derive(clap::Args)]
pub struct BuildArgs {
    #[command(flatten)]
    product: ProductArgs,
    /// W,S,E,N in degrees (default: the region's bounds).
    #[arg(long, allow_hyphen_values = true, value_parser = bbox)]
    bbox: Option<BBox>,
    /// Samples per row (1 to 8193); the outer samples lie on the box edges.
    #[arg(long, value_parser = side())]
    width: usize,
    /// Samples per column (1 to 8193).
    #[arg(long, value_parser = side())]
    height: usize,
}

impl BuildArgs {
    pub fn run(self) -> Result<()> {
        self.product.make(|region, layer, format| {
            // Georeferenced with its west within ±180° (the same samples).
            let bbox = self.bbox.unwrap_or(region.bounds).turned_home();
            in_region(region, &bbox, "--bbox")?;
            Ok(produce::area(region, bbox, self.width, self.height, layer, format)?)
        })
    }
}

/// `sylva canopy`.
#[derive(clap::Args)]
pub struct CanopyArgs {
    /// LAS or LAZ files, read as one cloud (repeat for more).
    #[arg(long = "las", required = true)]
    las: Vec<PathBuf>,
    /// Cell side of the canopy height model, metres.
    #[arg(long, default_value_t = sylva::lidar::DEFAULT_CELL_M, value_parser = super::positive("metres"), allow_negative_numbers = true)]
    resolution: f64,
    /// The proxy (a GeoTIFF atlas of Wang tiles).
    #[arg(short, long)]
    output: PathBuf,
    /// Also write the canopy height model (GeoTIFF).
    #[arg(long)]
    chm: Option<PathBuf>,
    /// Also write a picture of the CHM beside 3 × 3 tiles of the proxy (PNG).
    #[arg(long)]
    preview: Option<PathBuf>,
    /// `EPSG:code` replacing the files' CRS.
    #[arg(long, value_parser = sylva::source::crs::parse_epsg)]
    crs: Option<u32>,
    /// Tile side in texels, a power of two from 8 to 4096 (default: about 64 m).
    #[arg(long, value_parser = tile_px)]
    tile_px: Option<usize>,
    /// Colours per tile edge, 1 to 4 (1: one periodic tile).
    #[arg(long, default_value_t = 2, value_parser = count_in(Layout::COLOURS))]
    colours: usize,
    /// Tiles per colour combination, 1 to 8.
    #[arg(long, default_value_t = 2, value_parser = count_in(Layout::VARIANTS))]
    variants: usize,
}

impl CanopyArgs {
    /// Builds the proxy and writes it with the CHM and preview asked for,
    /// all or none.
    pub fn run(self) -> Result<()> {
        let inputs: Vec<&Path> = self.las.iter().map(PathBuf::as_path).collect();
        // The same points twice would count every return twice.
        if let Some((_, twice)) = inputs.iter().enumerate().find(|(k, p)| inputs[..*k].contains(p)) {
            anyhow::bail!("{}: given twice to --las (its points would count twice)", twice.display());
        }
        let targets: Vec<&Path> = [Some(&self.output), self.chm.as_ref(), self.preview.as_ref()]
            .into_iter()
            .flatten()
            .map(PathBuf::as_path)
            .collect();
        let abandon = Abandon::watch();
        outputs::check(&inputs, &targets)?;
        let mut options = sylva::lidar::Options::new(self.las.clone(), self.resolution);
        (options.crs, options.tile_px) = (self.crs, self.tile_px);
        (options.colours, options.variants) = (self.colours, self.variants);
        let (model, set) = sylva::lidar::build(&options)?;
        let mut files = vec![(self.output.as_path(), model.proxy_tiff(&set)?)];
        if let Some(path) = &self.chm {
            files.push((path, model.chm_tiff()?));
        }
        if let Some(path) = &self.preview {
            files.push((path, model.preview_png(&set, 3, 0)?));
        }
        abandon.writing(|| outputs::write_all(&files.iter().map(|(p, b)| (*p, b.as_slice())).collect::<Vec<_>>()))?;
        super::print(model.report(&set))?;
        Ok(())
    }
}

/// `sylva info`.
#[derive(clap::Args)]
pub struct InfoArgs {
    /// Region configuration (default: the embedded demo region).
    #[arg(long)]
    config: Option<PathBuf>,
}

impl InfoArgs {
    pub fn run(self) -> Result<()> {
        super::print(sylva::config::load(self.config.as_deref())?.describe())?;
        Ok(())
    }
}

/// Refuses an area that does not meet the region: its file would hold no
/// data (the server answers 404 there).
fn in_region(region: &Region, area: &BBox, what: &str) -> Result<()> {
    let r = region.bounds;
    match area.meets(&r) {
        true => Ok(()),
        false => Err(super::usage(format_args!(
            "{what} does not meet the region; its bounds are {},{},{},{}",
            r.west, r.south, r.east, r.north
        ))),
    }
}

/// `--width`, `--height`: 1 to [`sylva::grid::MAX_REQUEST_SIDE`].
fn side() -> clap::builder::RangedU64ValueParser<usize> {
    count_in(1..=sylva::grid::MAX_REQUEST_SIDE)
}

/// An option's parser of a count within `range`.
fn count_in(range: RangeInclusive<usize>) -> clap::builder::RangedU64ValueParser<usize> {
    let (min, max) = range.into_inner();
    clap::builder::RangedU64ValueParser::<usize>::new().range(min as u64..=max as u64)
}

/// `--tile-px`: a power of two in [`Layout::TILE_PX`].
fn tile_px(text: &str) -> Result<usize, String> {
    let px = text.parse::<usize>().map_err(|e| e.to_string())?;
    Layout::check_tile_px(px).map(|()| px)
}

/// `--layer`.
fn layer(text: &str) -> Result<Layer, String> {
    Layer::parse(text)
        .ok_or_else(|| "unknown layer; expected one of dem, cover, canopy, cem, surface, max4, max32".into())
}

/// `--format`.
fn format(text: &str) -> Result<Format, String> {
    Format::parse(text).ok_or_else(|| "unknown format; expected bil16, bil32, png16 or tiff".into())
}

/// `--bbox`: `W,S,E,N`.
fn bbox(text: &str) -> Result<BBox, String> {
    BBox::parse(text).map_err(|e| e.to_string())
}

/// Writes the product atomically and reports it.
fn write(path: &Path, product: &Product) -> Result<()> {
    outputs::write_all(&[(path, &product.encoded.bytes)])?;
    let g = &product.grid;
    sylva::outputs::say(format_args!(
        "{}: {}×{} samples, {} bytes, {:.1} ms",
        path.display(),
        g.width(),
        g.height(),
        product.encoded.bytes.len(),
        product.stats.total().as_secs_f64() * 1e3
    ));
    if let Some(q) = product.encoded.quantization {
        sylva::outputs::say(format_args!("  16-bit codes: value = {} + {} · code", q.offset, q.scale));
    }
    if product.encoded.clamped > 0 {
        sylva::outputs::say(format_args!(
            "  warning: {} samples were outside the 16-bit range and were clamped",
            product.encoded.clamped
        ));
    }
    if product.no_data {
        sylva::outputs::say(format_args!(
            "  warning: every sample is nodata (the area holds none of the sources' data)"
        ));
    }
    Ok(())
}
