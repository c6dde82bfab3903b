//! Stage two of the configuration: checks every value and opens every source,
//! producing a [`Region`]. Errors name the file and the problem.

use super::{Config, LandcoverConfig, LandcoverKind, UpstreamConfig};
use crate::canopy::{CanopyProxy, ProceduralProxy, TiledProxy};
use crate::cem::colorkey::{ColorKey, LabKey};
use crate::cem::landcover::{ForestTypes, Landcover, Rule};
use crate::cem::surface::SurfaceType;
use crate::demo;
use crate::encode::Quantization;
use crate::grid::{BBox, Sector, TileGrid};
use crate::raster::morphology::MorphOp;
use crate::region::{Forest, Region};
use crate::source::{
    self, BlockCache, Blocks, GeoRaster, Georef, NodataPolicy, OpenOptions, PixelSource, Reducer, SourceError,
};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use thiserror::Error;

/// A configuration that cannot be used.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The configuration file cannot be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not valid TOML for a Sylva configuration.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong and where.
        message: String,
    },
    /// A source named by the configuration cannot be opened.
    #[error(transparent)]
    Source(#[from] SourceError),
}

/// Loads the region of a configuration file, or the demo region without one.
pub fn load(path: Option<&Path>) -> Result<Region, ConfigError> {
    load_with_config(path).map(|(_, region)| region)
}

/// Loads a configuration file (or the defaults without one) and its region.
pub fn load_with_config(path: Option<&Path>) -> Result<(Config, Region), ConfigError> {
    let (config, base, label) = match path {
        Some(path) => (parse_file(path)?, base_of(path), path),
        None => (Config::default(), Path::new("."), Path::new("<built-in defaults>")),
    };
    let region = region_from(&config, base, label)?;
    Ok((config, region))
}

/// A configuration file and the files it names (none without one): the
/// inputs of a run that loads it.
pub fn input_files(path: Option<&Path>) -> Result<Vec<PathBuf>, ConfigError> {
    let Some(path) = path else { return Ok(Vec::new()) };
    let mut files = parse_file(path)?.files(base_of(path));
    files.push(path.to_path_buf());
    Ok(files)
}

/// The directory a configuration file's relative paths start from.
pub fn base_of(path: &Path) -> &Path {
    path.parent().unwrap_or(Path::new("."))
}

/// Reads and parses a configuration file (stage one only).
pub fn parse_file(path: &Path) -> Result<Config, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.into(), source })?;
    toml::from_str(&text).map_err(|e| ConfigError::Invalid { path: path.into(), message: e.to_string() })
}

/// Least block cache: below a few tiles' worth of source blocks every tile
/// decodes its blocks again (0 MiB made a 256² build 15× slower).
const MIN_CACHE_MB: u64 = 16;
/// Most block cache, MiB (1 TiB).
const MAX_CACHE_MB: u64 = 1 << 20;

/// Checks `config` (read from `label`, relative paths from `base`) and opens
/// its sources.
pub fn region_from(config: &Config, base: &Path, label: &Path) -> Result<Region, ConfigError> {
    let invalid = |message: String| ConfigError::Invalid { path: label.into(), message };
    let tiles = TileGrid::new(config.grid.level0_delta_deg, config.grid.tile_samples)
        .map_err(|e| invalid(format!("[grid] {e}")))?;
    // Check every value before opening any file.
    check_values(config).map_err(invalid)?;
    warn_of_slow_upstreams(config);
    // Data from upstream servers expires, in the block cache as in the tile cache.
    let upstream_ttl = upstreams(config).map(|(_, u)| std::time::Duration::from_secs(u.ttl_s)).min();
    let cache = BlockCache::expiring(config.cache.memory_mb * 1024 * 1024, upstream_ttl);
    let landcover_rule =
        config.landcover.as_ref().map(rule).transpose().map_err(|m| invalid(format!("[landcover] {m}")))?;
    let types = forest_types(config).map_err(invalid)?;
    let resolve = |p: &PathBuf| if p.is_absolute() { p.clone() } else { base.join(p) };
    let (dem, bounds, name) = open_dem(config, &resolve, &cache, &invalid)?;
    let demo = config.dem.path.is_none() && config.dem.upstream.is_none();
    let (landcover, map) = match (&config.landcover, landcover_rule, demo) {
        (Some(lc), Some(rule), _) => {
            let (l, m) = landcover(lc, (rule, types), &resolve, &cache, &|m| invalid(format!("[landcover] {m}")))?;
            overlaps(&l, &dem).map_err(|m| invalid(format!("[landcover] {m}")))?;
            (Some(l), m)
        }
        (None, _, true) => {
            let (l, m) = demo_landcover(&cache)?;
            (Some(l), m)
        }
        _ => (None, None),
    };
    let fallback: Arc<dyn CanopyProxy> = Arc::new(ProceduralProxy::new(config.canopy.clone()));
    Ok(Region {
        name: config.name.clone().unwrap_or(name),
        version: version_key(config, base),
        upstream_ttl,
        tiles,
        bounds,
        dem,
        dem_resampling: config.dem.resampling,
        landcover,
        map,
        proxy: fallback.clone(),
        forests: forests(config, &fallback, &resolve, &invalid)?,
        heights_16: Quantization { offset: config.encoding.png16_offset_m, scale: config.encoding.png16_scale_m },
        cache,
    })
}

/// The scalar settings of `config` checked: a message naming the first
/// that is out of range.
fn check_values(config: &Config) -> Result<(), String> {
    let memory_mb = config.cache.memory_mb;
    if !(MIN_CACHE_MB..=MAX_CACHE_MB).contains(&memory_mb) {
        return Err(format!("[cache] memory_mb = {memory_mb}: must be {MIN_CACHE_MB} to {MAX_CACHE_MB}"));
    }
    let enc = &config.encoding;
    if !(enc.png16_scale_m > 0.0 && enc.png16_scale_m.is_finite()) {
        return Err(format!("[encoding] png16_scale_m must be positive, got {}", enc.png16_scale_m));
    }
    if !enc.png16_offset_m.is_finite() {
        return Err(format!("[encoding] png16_offset_m must be a finite number, got {}", enc.png16_offset_m));
    }
    config.dem.nodata.check().map_err(|m| format!("[dem] nodata: {m}"))?;
    config.canopy.check().map_err(|m| format!("[canopy] {m}"))?;
    config.tile_cache.check().map_err(|m| format!("[tile_cache] {m}"))?;
    for (section, up) in upstreams(config) {
        up.check().map_err(|m| format!("{section} {m}"))?;
    }
    config.server.check().map_err(|m| format!("[server] {m}"))
}

/// The configuration's upstream servers, each with its section's name.
fn upstreams(config: &Config) -> impl Iterator<Item = (&'static str, &UpstreamConfig)> {
    let landcover = config.landcover.as_ref().and_then(|l| l.upstream.as_ref());
    [("[dem.upstream]", config.dem.upstream.as_ref()), ("[landcover.upstream]", landcover)]
        .into_iter()
        .filter_map(|(section, up)| Some((section, up?)))
}

/// Warns where an upstream's retries outlast a request to the server: a
/// request that needs a block read from it while it fails is answered
/// "took too long" before the upstream is blamed.
fn warn_of_slow_upstreams(config: &Config) {
    let request = config.server.request_timeout_s;
    for (section, up) in upstreams(config) {
        let longest = up.longest_read();
        if longest.as_secs_f64() > request {
            tracing::warn!(
                "{section} a failing upstream holds a read up to {:.1} s (timeout_ms, retries, backoff_ms), longer than [server] request_timeout_s = {request}: requests then time out before the upstream is named",
                longest.as_secs_f64()
            );
        }
    }
}

/// The region's DEM, its bounds and its name: a file, an upstream server,
/// or the embedded demo.
fn open_dem(
    config: &Config,
    resolve: &impl Fn(&PathBuf) -> PathBuf,
    cache: &Arc<BlockCache>,
    invalid: &dyn Fn(String) -> ConfigError,
) -> Result<(GeoRaster, BBox, String), ConfigError> {
    Ok(match (&config.dem.path, &config.dem.upstream) {
        (Some(_), Some(_)) => return Err(invalid("[dem] give a path or an upstream, not both".into())),
        (None, Some(up)) => {
            let invalid = |m: String| invalid(format!("[dem.upstream] {m}"));
            let bounds = up.bbox().map_err(invalid)?;
            let dem = upstream(up, cache, &invalid)?;
            if dem.base().source().bands() != 1 {
                return Err(invalid(format!(
                    "{}: answers a picture (three bands); a DEM's upstream answers FORMAT=application/bil32 or is a Terrarium template",
                    up.url
                )));
            }
            (dem, bounds, up.url.clone())
        }
        (Some(path), None) => {
            let crs = parse_crs(&config.dem.crs).map_err(|m| invalid(format!("[dem] {m}")))?;
            let options = OpenOptions { crs, nodata: config.dem.nodata.clone(), classes: false };
            let dem =
                source::open_file(&resolve(path), &options, cache).map_err(|e| invalid(format!("[dem] path: {e}")))?;
            let bands = dem.base().source().bands();
            if bands != 1 {
                let file = resolve(path);
                return Err(invalid(format!("[dem] path: {} has {bands} bands; a DEM has one", file.display())));
            }
            let bounds = dem.bounds().bbox();
            let name = path.file_stem().map_or_else(|| "dem".into(), |s| s.to_string_lossy().into_owned());
            (dem, bounds, name)
        }
        (None, None) => {
            let d = demo::sources()?;
            let pixels = source::nodata::apply(d.dem, &config.dem.nodata, cache);
            (GeoRaster::new(pixels, d.dem_georef, &[Reducer::Mean], cache), demo::BBOX, demo::NAME.to_string())
        }
    })
}

/// Which revision of Sylva's products a cached tile holds: change it with
/// any change to the code that changes some tile's bytes, so that caches
/// seeded before it are not served beside tiles made after it.
const PRODUCT_REVISION: &str = "2026-12-07, 34th sitting: a sample within 1e-6 of a step of a source pixel is that pixel's (nodata beside it no longer spreads)";

/// A key that changes with anything that changes a tile's bytes: every
/// setting, the size and time of every source file, and the products'
/// revision.
fn version_key(config: &Config, base: &Path) -> String {
    // Only what changes a tile's bytes: not where tiles are kept or served.
    let bytes_only = Config { server: Default::default(), tile_cache: Default::default(), ..config.clone() };
    let mut text = toml::to_string(&bytes_only).unwrap_or_default();
    text.push_str(PRODUCT_REVISION);
    // Each file as the configuration names it, so that processes reading it
    // from other working directories share one key.
    for path in config.named_files() {
        let meta = std::fs::metadata(base.join(path)).ok();
        let stamp =
            meta.map(|m| (m.len(), m.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())));
        text.push_str(&format!("{path:?}{stamp:?}"));
    }
    format!("v{:016x}", crate::cache::digest(text.as_bytes()))
}

/// An upstream server as a source.
#[cfg(feature = "http")]
fn upstream(
    up: &UpstreamConfig,
    cache: &Arc<BlockCache>,
    invalid: &dyn Fn(String) -> ConfigError,
) -> Result<GeoRaster, ConfigError> {
    source::remote::open(up, cache).map_err(|e| invalid(e.to_string()))
}

/// Without the `http` feature there is no client to reach an upstream.
#[cfg(not(feature = "http"))]
fn upstream(
    up: &UpstreamConfig,
    _: &Arc<BlockCache>,
    invalid: &dyn Fn(String) -> ConfigError,
) -> Result<GeoRaster, ConfigError> {
    Err(invalid(format!("upstream {} needs Sylva built with the `http` feature", up.url)))
}

/// The optional `crs = "EPSG:code"` of a source.
fn parse_crs(text: &Option<String>) -> Result<Option<u32>, String> {
    text.as_deref().map(crate::source::crs::parse_epsg).transpose()
}

/// The land-cover raster and, for a map, the map itself (its colours shade
/// the relief preview); `invalid` turns a message into a configuration error.
fn landcover(
    lc: &LandcoverConfig,
    (rule, types): (Rule, ForestTypes),
    resolve: &impl Fn(&PathBuf) -> PathBuf,
    cache: &Arc<BlockCache>,
    invalid: &dyn Fn(String) -> ConfigError,
) -> Result<(GeoRaster, Option<GeoRaster>), ConfigError> {
    let (input, georef) = match (&lc.path, &lc.upstream) {
        (Some(_), Some(_)) => return Err(invalid("give a path or an upstream, not both".into())),
        (None, Some(up)) => {
            let raster = upstream(up, cache, &|m| invalid(format!("upstream: {m}")))?;
            (raster.base().clone(), raster.georef().clone())
        }
        (Some(path), None) => {
            let crs = parse_crs(&lc.crs).map_err(invalid)?;
            let options =
                OpenOptions { crs, nodata: NodataPolicy::Propagate, classes: lc.kind == LandcoverKind::Classes };
            let raster =
                source::open_file(&resolve(path), &options, cache).map_err(|e| invalid(format!("path: {e}")))?;
            (raster.base().clone(), raster.georef().clone())
        }
        (None, None) if lc.kind == LandcoverKind::Map => {
            let d = demo::sources()?;
            (Blocks::new(d.map, cache), d.map_georef)
        }
        (None, None) => return Err(invalid(format!("kind {:?} needs a path or an upstream", lc.kind.name()))),
    };
    let bands = input.source().bands();
    let name = input.source().name().display();
    if lc.kind == LandcoverKind::Map && bands < 3 {
        return Err(invalid(format!("a map needs three bands (R, G, B); {name} has {bands}")));
    }
    if lc.kind != LandcoverKind::Map && bands != 1 {
        return Err(invalid(format!(
            "kind {:?} reads one band; {name} has {bands} (an RGB map or orthophoto is kind \"map\")",
            lc.kind.name()
        )));
    }
    let map =
        (lc.kind == LandcoverKind::Map).then(|| GeoRaster::new(input.clone(), georef.clone(), &[Reducer::Mean], cache));
    Ok((derived(input, georef, rule, types, cache), map))
}

/// Refuses land cover that covers none of the DEM (cover 0 everywhere and
/// the CEM the bare DEM: a wrong file, or a wrong CRS).
fn overlaps(landcover: &GeoRaster, dem: &GeoRaster) -> Result<(), String> {
    if landcover.bounds().meets_on_globe(&dem.bounds()) {
        return Ok(());
    }
    let span = |s: Sector| format!("{:.4}..{:.4}° E, {:.4}..{:.4}° N", s.min_lon, s.max_lon, s.min_lat, s.max_lat);
    Err(format!("covers none of the DEM: it spans {}, the DEM {}", span(landcover.bounds()), span(dem.bounds())))
}

/// Cover (mean), classes (decimated), covers of forest types (mean).
fn derived(input: Blocks, georef: Georef, rule: Rule, types: ForestTypes, cache: &Arc<BlockCache>) -> GeoRaster {
    let pixels: Arc<dyn PixelSource> = Arc::new(Landcover::with_types(input, rule, types));
    GeoRaster::new(Blocks::new(pixels, cache), georef, &[Reducer::Mean, Reducer::Decimate, Reducer::Mean], cache)
}

/// The demo's map with the demo's keys and the dissertation's close, and the
/// map itself.
fn demo_landcover(cache: &Arc<BlockCache>) -> Result<(GeoRaster, Option<GeoRaster>), ConfigError> {
    let d = demo::sources()?;
    let keys =
        compile(&demo_keys()).map_err(|message| ConfigError::Invalid { path: "<demo palette>".into(), message })?;
    let rule = Rule::Map {
        keys,
        ops: vec![MorphOp::Dilate, MorphOp::Dilate, MorphOp::Erode, MorphOp::Erode],
        radius_px: 1,
        blur_px: 1,
    };
    let input = Blocks::new(d.map, cache);
    let map = GeoRaster::new(input.clone(), d.map_georef.clone(), &[Reducer::Mean], cache);
    Ok((derived(input, d.map_georef, rule, ForestTypes::default(), cache), Some(map)))
}

/// Colour keys of the demo map's palette.
pub fn demo_keys() -> Vec<ColorKey> {
    use demo::palette as p;
    let key = |rgb: [u8; 3], surface| ColorKey {
        color: format!("#{:02x}{:02x}{:02x}", rgb[0], rgb[1], rgb[2]),
        tolerance: 10.0,
        surface,
    };
    vec![
        key(p::FOREST, SurfaceType::Forest),
        key(p::WATER, SurfaceType::Water),
        key(p::SHORE, SurfaceType::Water),
        key(p::ROCK, SurfaceType::Rock),
        key(p::SCREE, SurfaceType::Rock),
    ]
}

fn compile(keys: &[ColorKey]) -> Result<Vec<LabKey>, String> {
    keys.iter().map(ColorKey::compile).collect()
}

/// A map's close unless one is given (Figure 6.3: "2 passes of 3x3 filter
/// kernels were used for the dilate and erode stages").
const DEFAULT_CLOSE: &str = "DDEE";
/// A map's close kernel radius unless one is given, pixels (3 × 3).
const DEFAULT_CLOSE_RADIUS_PX: usize = 1;
/// A map's blur radius unless one is given, pixels.
const DEFAULT_BLUR_RADIUS_PX: usize = 1;

/// Largest close and blur radius on a map, pixels (a map's symbols are a
/// few pixels wide; the kernels grow with the square of the radius).
const MAX_MAP_RADIUS_PX: usize = 32;

fn rule(lc: &LandcoverConfig) -> Result<Rule, String> {
    if let Some(key) = foreign_option(lc) {
        return Err(format!("{key} does not apply to kind {:?}", lc.kind.name()));
    }
    match lc.kind {
        LandcoverKind::Map => {
            let keys = compile(lc.keys.as_deref().unwrap_or(&demo_keys()))?;
            if !keys.iter().any(|k| k.surface == SurfaceType::Forest) {
                return Err("no colour key marks forest".into());
            }
            let close = lc.close.as_deref().unwrap_or(DEFAULT_CLOSE);
            let ops = MorphOp::parse_sequence(close)
                .ok_or_else(|| format!("close {close:?} must be a sequence of D and E"))?;
            let radius_px = lc.close_radius_px.unwrap_or(DEFAULT_CLOSE_RADIUS_PX);
            let blur_px = lc.blur_radius_px.unwrap_or(DEFAULT_BLUR_RADIUS_PX);
            for (key, px) in [("close_radius_px", radius_px), ("blur_radius_px", blur_px)] {
                if px > MAX_MAP_RADIUS_PX {
                    return Err(format!("{key} = {px}: at most {MAX_MAP_RADIUS_PX} pixels"));
                }
            }
            Ok(Rule::Map { keys, ops, radius_px, blur_px })
        }
        LandcoverKind::Classes => class_table(lc).map(Rule::Classes),
        LandcoverKind::Percent => linear(lc, 0.0, 100.0),
        // Canopy height models: below 1 m is ground or shrubs; trees from 3 m.
        LandcoverKind::CanopyHeight => linear(lc, 1.0, 3.0),
    }
}

/// A `[landcover]` option given that belongs to another kind: a sign of a
/// wrong `kind`, which would silently ignore it.
fn foreign_option(lc: &LandcoverConfig) -> Option<&'static str> {
    let map = [
        ("keys", lc.keys.is_some()),
        ("close", lc.close.is_some()),
        ("close_radius_px", lc.close_radius_px.is_some()),
        ("blur_radius_px", lc.blur_radius_px.is_some()),
    ];
    let linear = [("zero_at", lc.zero_at.is_some()), ("full_at", lc.full_at.is_some())];
    let classes = [("[[landcover.classes]]", !lc.classes.is_empty())];
    let foreign: &[(&'static str, bool)] = match lc.kind {
        LandcoverKind::Map => &[&linear[..], &classes[..]].concat(),
        LandcoverKind::Classes => &[&map[..], &linear[..]].concat(),
        LandcoverKind::Percent | LandcoverKind::CanopyHeight => &[&map[..], &classes[..]].concat(),
    };
    foreign.iter().find(|(_, given)| *given).map(|(key, _)| *key)
}

/// Forest types: index 0 is forest of no named type, `k` the `k`-th
/// `[[forest]]`; none without `[[forest]]` entries.
fn forest_types(config: &Config) -> Result<ForestTypes, String> {
    let mut names: HashMap<&str, u8> = HashMap::new();
    for (k, f) in config.forest.iter().enumerate() {
        let index = u8::try_from(k + 1).map_err(|_| "at most 255 [[forest]] types".to_string())?;
        if names.insert(f.name.as_str(), index).is_some() {
            return Err(format!("[[forest]] {:?} appears twice", f.name));
        }
    }
    let lookup = |name: &Option<String>, place: &str| match name {
        None => Ok(None),
        Some(n) => names.get(n.as_str()).copied().map(Some).ok_or_else(|| {
            format!(
                "{place}: forest = {n:?} names no [[forest]] type (known: {:?})",
                config.forest.iter().map(|f| &f.name).collect::<Vec<_>>()
            )
        }),
    };
    let Some(lc) = &config.landcover else { return Ok(ForestTypes::default()) };
    let default = lookup(&lc.forest, "[landcover]")?.unwrap_or(0);
    let mut by_class = HashMap::new();
    for entry in &lc.classes {
        let Some(t) = lookup(&entry.forest, "[[landcover.classes]]")? else { continue };
        if entry.surface != SurfaceType::Forest {
            return Err(format!(
                "[[landcover.classes]]: forest = {:?} on {} classes",
                entry.forest.as_deref().unwrap_or_default(),
                entry.surface.name()
            ));
        }
        let ranged = entry.ranges.iter().flat_map(|&[a, b]| a..=b);
        by_class.extend(entry.values.iter().copied().chain(ranged).map(|v| (v, t)));
    }
    let count = if config.forest.is_empty() { 0 } else { config.forest.len() + 1 };
    Ok(ForestTypes { count, default, by_class })
}

/// The proxies of the `[[forest]]` types: a file, point clouds, or the
/// procedural `fallback`.
fn forests(
    config: &Config,
    fallback: &Arc<dyn CanopyProxy>,
    resolve: &impl Fn(&PathBuf) -> PathBuf,
    invalid: &dyn Fn(String) -> ConfigError,
) -> Result<Vec<Forest>, ConfigError> {
    config
        .forest
        .iter()
        .map(|f| {
            // Each type its own arrangement of tiles.
            let seed = crate::cache::digest(f.name.as_bytes());
            if f.lidar.is_empty() && f.resolution_m.is_some() {
                return Err(invalid(format!(
                    "[[forest]] {:?}: resolution_m applies to lidar files, and none are given",
                    f.name
                )));
            }
            let proxy: Arc<dyn CanopyProxy> = match (&f.proxy, f.lidar.is_empty()) {
                (Some(_), false) => {
                    return Err(invalid(format!("[[forest]] {:?}: give a proxy or lidar files, not both", f.name)));
                }
                (Some(path), true) => {
                    let path = resolve(path);
                    let tiles = source::proxy::open(&path)
                        .map_err(|e| invalid(format!("[[forest]] {:?} proxy: {e}", f.name)))?;
                    Arc::new(TiledProxy::new(path.display().to_string(), tiles, seed))
                }
                (None, false) => {
                    let files = f.lidar.iter().map(resolve).collect();
                    let proxy = crate::lidar::proxy(
                        &crate::lidar::Options::new(files, f.resolution_m.unwrap_or(crate::lidar::DEFAULT_CELL_M)),
                        seed,
                    )
                    .map_err(|e| invalid(format!("[[forest]] {:?} lidar: {e}", f.name)))?;
                    Arc::new(proxy)
                }
                (None, true) => fallback.clone(),
            };
            Ok(Forest { name: f.name.clone(), proxy })
        })
        .collect()
}

fn linear(lc: &LandcoverConfig, zero_at: f32, full_at: f32) -> Result<Rule, String> {
    let (zero_at, full_at) = (lc.zero_at.unwrap_or(zero_at), lc.full_at.unwrap_or(full_at));
    if !(zero_at.is_finite() && full_at.is_finite() && zero_at != full_at) {
        return Err(format!("zero_at {zero_at} and full_at {full_at} must be finite and different"));
    }
    Ok(Rule::Linear { zero_at, full_at })
}

fn class_table(lc: &LandcoverConfig) -> Result<HashMap<i64, (SurfaceType, f32)>, String> {
    if lc.classes.is_empty() {
        return Err("kind \"classes\" needs [[landcover.classes]] entries".into());
    }
    let mut table = HashMap::new();
    for entry in &lc.classes {
        if let Some([a, b]) = entry.ranges.iter().find(|[a, b]| a > b) {
            return Err(format!(
                "the range [{a}, {b}] of {} classes is empty (write [{b}, {a}])",
                entry.surface.name()
            ));
        }
        let cover = entry.cover.unwrap_or(if entry.surface == SurfaceType::Forest { 1.0 } else { 0.0 });
        if !(0.0..=1.0).contains(&cover) {
            return Err(format!("cover {cover} of {} classes is outside [0, 1]", entry.surface.name()));
        }
        let ranged = entry.ranges.iter().flat_map(|&[a, b]| a..=b);
        for value in entry.values.iter().copied().chain(ranged) {
            if table.insert(value, (entry.surface, cover)).is_some() {
                return Err(format!("class {value} appears twice"));
            }
        }
    }
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_version_key_is_the_same_from_any_working_directory_and_follows_the_files() {
        // A scratch directory named relative to the package (the working
        // directory of unit tests) and absolutely.
        let relative = Path::new("target/version-key-test");
        let dir = std::env::current_dir().unwrap().join(relative);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("dem.tif"), b"one").unwrap();
        let config: Config = toml::from_str("[dem]\npath = \"dem.tif\"\n").unwrap();
        let key = version_key(&config, &dir);
        assert_eq!(key, version_key(&config, relative));
        std::fs::write(dir.join("dem.tif"), b"three").unwrap();
        assert_ne!(key, version_key(&config, &dir), "a changed file changes the key");
    }
}
