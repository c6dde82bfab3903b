//! Configuration, in two stages: serde structs with one `Default` each (this
//! file; `config/default.toml` shows every option at its default), then
//! validation into a checked [`crate::region::Region`] (`build`).
//!
//! With no file, or a file that names no DEM, the region is the embedded demo.
//! Relative paths are relative to the configuration file.

mod build;
mod upstream;

pub use build::{ConfigError, base_of, demo_keys, input_files, load, load_with_config, parse_file, region_from};
pub use upstream::{UpstreamConfig, UpstreamService};

use crate::canopy::ProxyParams;
use crate::cem::colorkey::ColorKey;
use crate::cem::surface::SurfaceType;
use crate::raster::resample::Resampling;
use crate::source::NodataPolicy;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The whole configuration file.
#[derive(Clone, Debug, Default, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// Region name (default: the demo's, or the DEM file's name).
    pub name: Option<String>,
    /// The tile grid.
    pub grid: GridConfig,
    /// The in-memory block cache.
    pub cache: CacheConfig,
    /// The elevation model.
    pub dem: DemConfig,
    /// Where forest and surface classes come from.
    pub landcover: Option<LandcoverConfig>,
    /// The procedural canopy proxy (forest of no named type, and types
    /// without a proxy of their own).
    pub canopy: ProxyParams,
    /// Forest types and their canopy proxies.
    pub forest: Vec<ForestConfig>,
    /// 16-bit encodings.
    pub encoding: EncodingConfig,
    /// The tile server.
    pub server: ServerConfig,
    /// Where encoded tiles are cached (shared by `serve` and `seed`).
    pub tile_cache: TileCacheConfig,
}

impl Config {
    /// The files this configuration names, as it names them.
    pub fn named_files(&self) -> impl Iterator<Item = &PathBuf> {
        let named = [self.dem.path.as_ref(), self.landcover.as_ref().and_then(|l| l.path.as_ref())];
        let forests = self.forest.iter().flat_map(|f| f.proxy.iter().chain(&f.lidar));
        named.into_iter().flatten().chain(forests)
    }

    /// The files this configuration reads, relative ones taken from `base`
    /// (the configuration file's directory): what no output may overwrite.
    pub fn files(&self, base: &std::path::Path) -> Vec<PathBuf> {
        self.named_files().map(|p| base.join(p)).collect()
    }
}

/// Where encoded tiles are cached.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct TileCacheConfig {
    /// `directory` or `redis`.
    pub backend: TileCacheBackend,
    /// directory: where (relative to the working directory).
    pub dir: PathBuf,
    /// redis: the server, `redis://host:port/db` or `redis+unix:///path`.
    pub redis_url: String,
    /// redis: prefix of every key.
    pub redis_prefix: String,
    /// A tile lock's expiry, seconds: its holder renews it every third of
    /// this while it computes; one that dies frees it this long after its
    /// last renewal, when another process may take it over.
    pub lock_ttl_s: f64,
    /// The cache's bound, bytes (given as a size: "20GiB"): the servers
    /// sharing it trim its least recently used tiles back to this size
    /// (`cache::quota`); `None`: unbounded.
    #[serde(deserialize_with = "size")]
    pub max_size: Option<u64>,
    /// How often the servers trim the cache to `max_size`, seconds (one of
    /// them each time).
    pub trim_interval_s: f64,
}

impl Default for TileCacheConfig {
    fn default() -> Self {
        TileCacheConfig {
            backend: TileCacheBackend::Directory,
            dir: PathBuf::from("cache"),
            redis_url: "redis://127.0.0.1:6379/0".into(),
            redis_prefix: "sylva:".into(),
            // Renewed every 3.3 s while held: a crashed holder delays its
            // tiles by at most 10 s, and a renewal may come 6 s late.
            lock_ttl_s: 10.0,
            max_size: None,
            trim_interval_s: 600.0,
        }
    }
}

impl TileCacheConfig {
    /// The backend, with the directory `dir_override` instead if given.
    pub fn backend(&self, dir_override: Option<&std::path::Path>) -> crate::cache::Backend {
        match (dir_override, self.backend) {
            (Some(dir), _) => crate::cache::Backend::Directory(dir.to_path_buf()),
            (None, TileCacheBackend::Directory) => crate::cache::Backend::Directory(self.dir.clone()),
            (None, TileCacheBackend::Redis) => {
                crate::cache::Backend::Redis { url: self.redis_url.clone(), prefix: self.redis_prefix.clone() }
            }
        }
    }

    /// The lock expiry and the bound's settings checked.
    fn check(&self) -> Result<(), String> {
        if self.max_size == Some(0) {
            return Err("max_size must be more than 0 bytes (leave it out for no bound)".into());
        }
        let within = |key: &str, value: f64, range: &std::ops::RangeInclusive<f64>| match range.contains(&value) {
            true => Ok(()),
            false => Err(format!("{key} = {value}: must be {} to {}", range.start(), range.end())),
        };
        within("lock_ttl_s", self.lock_ttl_s, &LOCK_TTL_S)?;
        within("trim_interval_s", self.trim_interval_s, &TRIM_INTERVAL_S)
    }

    /// How often the servers trim the cache to its bound (nonsense values
    /// become the default).
    pub fn trim_interval(&self) -> std::time::Duration {
        let s = self.trim_interval_s;
        std::time::Duration::from_secs_f64(if TRIM_INTERVAL_S.contains(&s) { s } else { 600.0 })
    }

    /// The lock expiry (nonsense values become the default).
    pub fn lock_ttl(&self) -> std::time::Duration {
        let s = self.lock_ttl_s;
        std::time::Duration::from_secs_f64(if LOCK_TTL_S.contains(&s) { s } else { 10.0 })
    }
}

/// A size as "500MiB", "20 GiB" or "1000000" (bytes) give it: bytes.
pub fn parse_size(text: &str) -> Result<u64, String> {
    text.trim()
        .parse::<bytesize::ByteSize>()
        .map(|s| s.as_u64())
        .map_err(|_| format!("not a size: {text:?} (e.g. 500MiB, 20GiB)"))
}

/// Bytes for people (IEC units: "1.5 GiB"), as [`parse_size`] reads them.
pub fn show_size(bytes: u64) -> String {
    bytesize::ByteSize::b(bytes).display().iec().to_string()
}

/// A size in a configuration file: a string [`parse_size`] reads, or a
/// number of bytes.
fn size<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<u64>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Given {
        Bytes(u64),
        Text(String),
    }
    match Given::deserialize(d) {
        Ok(Given::Bytes(n)) => Ok(Some(n)),
        Ok(Given::Text(text)) => parse_size(&text).map(Some).map_err(serde::de::Error::custom),
        Err(_) => Err(serde::de::Error::custom("not a size (e.g. \"500MiB\", \"20GiB\", or a number of bytes)")),
    }
}

/// Tile lock expiries, seconds: a second (renewed every third of it) to a
/// day.
const LOCK_TTL_S: std::ops::RangeInclusive<f64> = 1.0..=86_400.0;

/// Trim intervals, seconds: a minute (a trim walks the whole cache) to a day.
const TRIM_INTERVAL_S: std::ops::RangeInclusive<f64> = 60.0..=86_400.0;

/// Tile cache backends.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TileCacheBackend {
    /// A local (or network) directory.
    Directory,
    /// A Redis server.
    Redis,
}

/// A forest type and its canopy proxy (dissertation 6.3: "several distinct
/// canopy proxies for different surfaces, e.g., for deciduous or coniferous
/// forests"). Land cover names the type of its forest with `forest = "…"`.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ForestConfig {
    /// The type's name.
    pub name: String,
    /// A proxy made by `sylva canopy` (GeoTIFF).
    #[serde(default)]
    pub proxy: Option<PathBuf>,
    /// Or LAS/LAZ files to build the proxy from when the region loads.
    #[serde(default)]
    pub lidar: Vec<PathBuf>,
    /// Cell side of the canopy height model built from `lidar`, metres
    /// (default 0.5).
    #[serde(default)]
    pub resolution_m: Option<f64>,
}

/// `sylva serve`.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServerConfig {
    /// Address to listen on.
    pub bind: String,
    /// Encoded tiles kept in memory, MiB.
    pub memory_cache_mb: u64,
    /// Threads computing tiles; 0 = one per core.
    pub workers: usize,
    /// Tile computations waiting for a worker at most; more answer 503.
    pub queue: usize,
    /// Longest a request may take, seconds.
    pub request_timeout_s: f64,
    /// Largest WMS WIDTH and HEIGHT.
    pub max_size: usize,
    /// Largest tile halo, samples.
    pub max_halo: usize,
    /// `Cache-Control: max-age` of tiles, seconds.
    pub tile_max_age_s: u64,
    /// The URL clients reach the server at (for capabilities); default: from
    /// the request's Host header.
    pub public_url: Option<String>,
}

/// Most tile worker threads `[server] workers` may ask for.
pub const MAX_WORKERS: usize = 1024;
/// Most tile computations `[server] queue` may let wait.
pub const MAX_QUEUE: usize = 1 << 20;
/// Longest `[server] request_timeout_s`: a day.
pub const MAX_REQUEST_TIMEOUT_S: f64 = 86_400.0;
/// Largest `[server] max_halo`, samples.
pub const MAX_HALO: usize = 1024;

/// Checks an address to listen on: `HOST:PORT`, an IPv6 host bracketed
/// (`[::1]:8080`).
pub fn check_bind(bind: &str) -> Result<(), String> {
    let host_ok = |h: &str| !h.is_empty() && (!h.contains(':') || (h.starts_with('[') && h.ends_with(']')));
    match bind.rsplit_once(':') {
        Some((host, port)) if host_ok(host) && port.parse::<u16>().is_ok() => Ok(()),
        _ => Err("must be HOST:PORT".into()),
    }
}

impl ServerConfig {
    /// Checks every value: the message names the key, what it must be and
    /// what it is.
    pub fn check(&self) -> Result<(), String> {
        check_bind(&self.bind).map_err(|e| format!("bind = {:?}: {e}", self.bind))?;
        let within = |key: &str, value: usize, most: usize| {
            if value <= most { Ok(()) } else { Err(format!("{key} = {value}: must be at most {most}")) }
        };
        within("workers", self.workers, MAX_WORKERS)?;
        within("queue", self.queue, MAX_QUEUE)?;
        within("max_halo", self.max_halo, MAX_HALO)?;
        // No larger than a request may be.
        let most = crate::grid::MAX_REQUEST_SIDE;
        if !(1..=most).contains(&self.max_size) {
            return Err(format!("max_size = {}: must be 1 to {most}", self.max_size));
        }
        let t = self.request_timeout_s;
        if !(t > 0.0 && t <= MAX_REQUEST_TIMEOUT_S) {
            return Err(format!(
                "request_timeout_s = {t}: must be above 0 and at most {MAX_REQUEST_TIMEOUT_S} (a day)"
            ));
        }
        match &self.public_url {
            Some(url) if !(url.starts_with("http://") || url.starts_with("https://")) => {
                Err(format!("public_url = {url:?}: must start with http:// or https://"))
            }
            _ => Ok(()),
        }
    }
}

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig {
            bind: "127.0.0.1:8080".into(),
            memory_cache_mb: 32,
            workers: 0,
            // A few tiles per worker: deep enough to keep workers busy,
            // shallow enough that a burst is refused before it times out.
            queue: 64,
            request_timeout_s: 30.0,
            max_size: 4096,
            max_halo: 64,
            tile_max_age_s: 86_400,
            public_url: None,
        }
    }
}

/// World Wind tiling.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct GridConfig {
    /// Level-0 tile delta D0, degrees (must divide 180).
    pub level0_delta_deg: f64,
    /// Samples per tile side N (tiles share edge samples: spacing = delta / (N − 1)).
    pub tile_samples: u32,
}

impl Default for GridConfig {
    fn default() -> Self {
        // 36° level-0 tiles as World Wind's elevation models; 513 = 2⁹ + 1
        // samples so that a tile has 512 cells and mipmaps halve evenly.
        GridConfig { level0_delta_deg: 36.0, tile_samples: 513 }
    }
}

/// Block cache budget.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct CacheConfig {
    /// Decoded and derived source blocks kept in memory, MiB.
    pub memory_mb: u64,
}

impl Default for CacheConfig {
    fn default() -> Self {
        CacheConfig { memory_mb: 160 }
    }
}

/// The DEM.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct DemConfig {
    /// GeoTIFF or SRTM `.hgt` file; none (and no upstream) = the embedded
    /// demo region.
    pub path: Option<PathBuf>,
    /// Read the DEM from another server instead of a file.
    pub upstream: Option<UpstreamConfig>,
    /// `EPSG:code` overriding the file's own CRS.
    pub crs: Option<String>,
    /// nearest, bilinear or bicubic.
    pub resampling: Resampling,
    /// Voids: fill, constant or propagate.
    pub nodata: NodataPolicy,
}

impl Default for DemConfig {
    fn default() -> Self {
        DemConfig {
            path: None,
            upstream: None,
            crs: None,
            resampling: Resampling::Bilinear,
            nodata: NodataPolicy::default(),
        }
    }
}

/// Land cover: one of three kinds of raster.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LandcoverConfig {
    /// `map`, `classes`, `percent` or `canopy_height`.
    pub kind: LandcoverKind,
    /// The raster; none (and no upstream) = the demo's topographic map (kind
    /// `map` only).
    pub path: Option<PathBuf>,
    /// Read the raster from another server instead of a file.
    #[serde(default)]
    pub upstream: Option<UpstreamConfig>,
    /// `EPSG:code` overriding the file's own CRS.
    pub crs: Option<String>,
    /// map: colour keys (default: the demo map's palette).
    #[serde(default)]
    pub keys: Option<Vec<ColorKey>>,
    /// map: the close, as a sequence of D (dilate) and E (erode) passes
    /// (default "DDEE").
    #[serde(default)]
    pub close: Option<String>,
    /// map: kernel radius of each pass, pixels (1 = 3×3, the default).
    #[serde(default)]
    pub close_radius_px: Option<usize>,
    /// map: Gaussian blur radius after the close, pixels (0 = none; default 1).
    #[serde(default)]
    pub blur_radius_px: Option<usize>,
    /// classes: the class table.
    #[serde(default)]
    pub classes: Vec<ClassEntry>,
    /// percent / canopy_height: input value with cover 0.
    #[serde(default)]
    pub zero_at: Option<f32>,
    /// percent / canopy_height: input value with cover 1.
    #[serde(default)]
    pub full_at: Option<f32>,
    /// The forest type (a `[[forest]]` name) of forest that names none.
    #[serde(default)]
    pub forest: Option<String>,
}

/// Land-cover raster kinds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LandcoverKind {
    /// RGB topographic map or orthophoto with colour keys.
    Map,
    /// Classified raster with a class table.
    Classes,
    /// Tree canopy cover in percent (0–100 by default).
    Percent,
    /// Canopy height model in metres (cover 0 below 1 m, 1 from 3 m by default).
    CanopyHeight,
}

impl LandcoverKind {
    /// The name a configuration gives it.
    pub fn name(self) -> &'static str {
        match self {
            LandcoverKind::Map => "map",
            LandcoverKind::Classes => "classes",
            LandcoverKind::Percent => "percent",
            LandcoverKind::CanopyHeight => "canopy_height",
        }
    }
}

/// One row of a class table: classes that share a surface and cover.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ClassEntry {
    /// Class values.
    #[serde(default)]
    pub values: Vec<i64>,
    /// Inclusive ranges of class values.
    #[serde(default)]
    pub ranges: Vec<[i64; 2]>,
    /// Their surface type.
    pub surface: SurfaceType,
    /// Their vegetation cover in [0, 1] (default 1 for forest, else 0).
    pub cover: Option<f32>,
    /// Their forest type (a `[[forest]]` name).
    #[serde(default)]
    pub forest: Option<String>,
}

/// 16-bit encodings of heights.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct EncodingConfig {
    /// PNG16 height of code 0 (code 0 itself means nodata), metres.
    pub png16_offset_m: f64,
    /// PNG16 height step per code, metres.
    pub png16_scale_m: f64,
}

impl Default for EncodingConfig {
    fn default() -> Self {
        let q = crate::encode::Quantization::PNG16_HEIGHTS;
        EncodingConfig { png16_offset_m: q.offset, png16_scale_m: q.scale }
    }
}
