//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};
use sylva::raster::Raster;
use sylva::region::Region;

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A file under `../shared/data`, which must exist.
pub fn data(rel: &str) -> PathBuf {
    let path = repo().join("../shared/data").join(rel);
    assert!(path.exists(), "test data {} is missing: clone the repository next to ../shared", path.display());
    path
}

/// The region of a file in `config/` (e.g. `examples/rmnp.toml`).
pub fn region(config: &str) -> Region {
    let path = repo().join("config").join(config);
    match sylva::config::load(Some(&path)) {
        Ok(r) => r,
        Err(e) => panic!("{}: {e}", path.display()),
    }
}

/// The tile of the geographic quadtree's zoom `z` (two 180° tiles at zoom
/// 0) holding the demo's middle, 10.125° E, 46.375° N: its side in degrees,
/// its column and its row counted from the south.
pub fn demo_middle_tile(z: u32) -> (f64, u64, u64) {
    let size = 180.0 / f64::from(1u32 << z);
    (size, ((10.125 + 180.0) / size) as u64, ((46.375 + 90.0) / size) as u64)
}

/// The embedded demo region.
pub fn demo() -> Region {
    match sylva::config::load(None) {
        Ok(r) => r,
        Err(e) => panic!("demo: {e}"),
    }
}

/// Bitwise equality of two f32 rasters (NaN equal to NaN); the first
/// difference is reported.
pub fn assert_same(a: &Raster<f32>, b: &Raster<f32>, what: &str) {
    assert_eq!((a.width(), a.height()), (b.width(), b.height()), "{what}: sizes differ");
    for y in 0..a.height() {
        for x in 0..a.width() {
            let (u, v) = (a.get(x, y), b.get(x, y));
            assert!(
                u.to_bits() == v.to_bits() || (u.is_nan() && v.is_nan()),
                "{what}: sample ({x}, {y}) is {u} vs {v}"
            );
        }
    }
}

/// A small deterministic generator for test cases (xorshift).
pub struct Rng(pub u64);

impl Rng {
    /// A number in `0..n`.
    pub fn below(&mut self, n: u64) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0 % n.max(1)
    }
}

/// A temporary directory removed on drop.
pub struct TempDir(pub PathBuf);

impl TempDir {
    /// A fresh directory named after `tag`.
    pub fn new(tag: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("sylva-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        TempDir(dir)
    }

    /// A path inside the directory.
    pub fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The share of a PNG's pixels in the `columns` (fractions of its width)
/// that are not the sky's colour.
pub fn ground_share(file: &Path, columns: std::ops::Range<f64>) -> f64 {
    let image = image::open(file).unwrap_or_else(|e| panic!("{}: {e}", file.display())).to_rgba8();
    let sky = sylva::client::reference::rgba(sylva::client::raycast::SKY);
    let is_sky = |p: &image::Rgba<u8>| p.0.iter().zip(sky).all(|(&a, b)| a.abs_diff(b) <= 2);
    let width = f64::from(image.width());
    let inside = |x: u32| columns.contains(&((f64::from(x) + 0.5) / width));
    let pixels: Vec<_> = image.enumerate_pixels().filter(|(x, _, _)| inside(*x)).map(|(_, _, p)| p).collect();
    pixels.iter().filter(|p| !is_sky(p)).count() as f64 / pixels.len() as f64
}

/// A region over in-memory rasters in EPSG:4326: `dem` and, optionally, a
/// canopy-cover percentage, both `w × h` pixels of `pixel_deg` with the
/// north-west pixel centre at `(lon0, lat0)`.
pub fn synthetic(dem: Raster<f32>, cover_percent: Option<Raster<f32>>, lon0: f64, lat0: f64, pixel_deg: f64) -> Region {
    use std::sync::Arc;
    use sylva::cem::landcover::{Landcover, Rule};
    use sylva::source::memory::MemorySource;
    use sylva::source::{BlockCache, Blocks, Crs, GeoRaster, Georef, Reducer};
    let cache = BlockCache::new(1 << 28);
    let georef =
        Georef { crs: Arc::new(Crs::wgs84()), x0: lon0, y0: lat0, dx: pixel_deg, dy: -pixel_deg, overhang: 0.5 };
    let (w, h) = (dem.width(), dem.height());
    let memory =
        |name: &str, r: Raster<f32>| Blocks::new(Arc::new(MemorySource::new(name, vec![r]).expect("raster")), &cache);
    let dem = GeoRaster::new(memory("<synthetic dem>", dem), georef.clone(), &[Reducer::Mean], &cache);
    let landcover = cover_percent.map(|c| {
        let lc = Landcover::new(memory("<synthetic cover>", c), Rule::Linear { zero_at: 0.0, full_at: 100.0 });
        GeoRaster::new(Blocks::new(Arc::new(lc), &cache), georef.clone(), &[Reducer::Mean, Reducer::Decimate], &cache)
    });
    let half = 0.5 * pixel_deg;
    Region {
        name: "synthetic".into(),
        version: "synthetic".into(),
        upstream_ttl: None,
        tiles: sylva::grid::TileGrid::new(36.0, 513).expect("grid"),
        bounds: sylva::grid::BBox {
            west: lon0 - half,
            north: lat0 + half,
            east: lon0 + (w as f64 - 0.5) * pixel_deg,
            south: lat0 - (h as f64 - 0.5) * pixel_deg,
        },
        dem,
        dem_resampling: sylva::raster::resample::Resampling::Bilinear,
        landcover,
        map: None,
        proxy: Arc::new(sylva::canopy::ProceduralProxy::new(Default::default())),
        forests: Vec::new(),
        heights_16: sylva::encode::Quantization::PNG16_HEIGHTS,
        cache,
    }
}
