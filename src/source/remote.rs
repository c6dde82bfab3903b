//! Upstream sources: a DEM or a map read from another server over HTTP — an
//! XYZ Terrarium tile service, or a WMS (another `sylva serve`, MapServer,
//! GeoServer) — block by block through the block cache (dissertation 6.5: the
//! server is a proxy in front of the data).
//!
//! Requests go through a [`Link`] (timeouts, retries with backoff, a
//! circuit breaker). Overviews are the upstream's own coarser zoom levels or resolutions.

use super::link::Link;
use super::{BLOCK, BlockCache, Blocks, Crs, GeoRaster, Georef, PixelSource, SourceError};
use crate::config::{UpstreamConfig, UpstreamService};
use crate::grid::BBox;
use crate::grid::mercator::HALF_WORLD_M;
use crate::raster::Raster;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Opens an upstream as a georeferenced source with native overviews.
pub fn open(config: &UpstreamConfig, cache: &Arc<BlockCache>) -> Result<GeoRaster, SourceError> {
    let name = PathBuf::from(&config.url);
    let bad = |problem: String| SourceError::Malformed { path: name.clone(), problem };
    let link = Arc::new(Link::new(&config.into()));
    match config.service {
        UpstreamService::Terrarium => {
            if !(config.url.contains("{z}") && config.url.contains("{x}") && config.url.contains("{y}"))
                || config.zoom > 22
            {
                return Err(bad("a Terrarium template needs {z}, {x} and {y}, and zoom ≤ 22".into()));
            }
            let crs = Crs::from_epsg(3857).map_err(|source| SourceError::Crs { path: name.clone(), source })?;
            Ok(terrarium(config, link, crs, cache))
        }
        UpstreamService::Wms => {
            let area = config.bbox().map_err(bad)?;
            let res = config.resolution_deg;
            if !(res > 0.0 && res.is_finite()) {
                return Err(bad(format!("resolution_deg {res} must be positive")));
            }
            // The finest resolution whose coarsest overview is at most
            // MAX_COARSEST_BLOCKS blocks across the area.
            let span = (area.east - area.west).max(area.north - area.south);
            let finest = span / ((1u64 << MAX_HALVINGS) as f64 * (BLOCK * MAX_COARSEST_BLOCKS) as f64);
            if res < finest {
                let b = config.bounds;
                return Err(bad(format!("resolution_deg {res} is too fine for bounds {b:?}: at least {finest:.1e}")));
            }
            let request = WmsUrl::parse(&config.url).map_err(bad)?;
            Ok(wms(config, request, link, area, cache))
        }
    }
}

/// Overviews of a WMS upstream: its resolution halved at most this often.
const MAX_HALVINGS: u32 = 21;
/// Blocks across the coarsest overview, at most: a request over the whole
/// area reads no more than this squared.
const MAX_COARSEST_BLOCKS: usize = 16;

/// What a WMS upstream's URL asks for, checked: the format it answers and
/// how its boxes are written.
#[derive(Clone, Debug, PartialEq)]
struct WmsUrl {
    /// The URL as configured (every parameter but the box and the size).
    url: String,
    /// A map's colours (`image/png`, three bands) rather than float32 values.
    picture: bool,
    /// Boxes written latitude first (WMS 1.3.0 in EPSG:4326).
    lat_first: bool,
}

impl WmsUrl {
    /// Checks a GetMap URL without `BBOX`, `WIDTH` and `HEIGHT`: HTTP,
    /// `FORMAT` `application/bil32` or `image/png`, `CRS`/`SRS`
    /// `CRS:84` or `EPSG:4326` (with a `VERSION` to fix its axis order).
    fn parse(url: &str) -> Result<WmsUrl, String> {
        let uri = url.parse::<ureq::http::Uri>().map_err(|_| "not a URL".to_string())?;
        if !matches!(uri.scheme_str(), Some("http" | "https")) || uri.host().is_none_or(str::is_empty) {
            return Err("not an http:// or https:// URL with a host".into());
        }
        let params: Vec<(String, String)> = form_urlencoded::parse(uri.query().unwrap_or("").as_bytes())
            .map(|(k, v)| (k.to_ascii_uppercase(), v.trim().to_string()))
            .collect();
        let get = |key: &str| params.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str());
        if let Some(key) = ["BBOX", "WIDTH", "HEIGHT"].into_iter().find(|k| get(k).is_some()) {
            return Err(format!("leave {key} out of the URL: each block's box and size are added to it"));
        }
        let picture = match get("FORMAT").map(str::to_ascii_lowercase).as_deref() {
            Some("application/bil32") => false,
            Some("image/png") => true,
            other => {
                let named = other.map_or("no FORMAT".to_string(), |f| format!("FORMAT={f}"));
                return Err(format!("{named}: read are application/bil32 (values) and image/png (a map's colours)"));
            }
        };
        let version = get("VERSION");
        let lat_first = match (get("CRS").map(|c| ("CRS", c)).or(get("SRS").map(|c| ("SRS", c))), version) {
            (Some((_, c)), _) if c.eq_ignore_ascii_case("CRS:84") => false,
            (Some(("SRS", c)), _) if c.eq_ignore_ascii_case("EPSG:4326") => false,
            (Some((_, c)), Some(v)) if c.eq_ignore_ascii_case("EPSG:4326") => v.starts_with("1.3"),
            (Some((_, c)), None) if c.eq_ignore_ascii_case("EPSG:4326") => {
                return Err(
                    "CRS=EPSG:4326 without VERSION: its axis order depends on the version (or name CRS=CRS:84)".into(),
                );
            }
            (Some((key, c)), _) => {
                return Err(format!("{key}={c}: boxes are asked in degrees, CRS=CRS:84 or EPSG:4326"));
            }
            (None, _) => return Err("no CRS (or SRS): name CRS=CRS:84".into()),
        };
        Ok(WmsUrl { url: url.to_string(), picture, lat_first })
    }

    /// The GetMap of the box `[west, south, east, north]` at `size` pixels.
    fn get_map(&self, [west, south, east, north]: [f64; 4], (w, h): (usize, usize)) -> String {
        let sep = if self.url.contains('?') { '&' } else { '?' };
        let bbox = if self.lat_first { [south, west, north, east] } else { [west, south, east, north] };
        let [a, b, c, d] = bbox;
        format!("{}{sep}BBOX={a},{b},{c},{d}&WIDTH={w}&HEIGHT={h}", self.url)
    }
}

/// A Terrarium service as a Web Mercator raster (`crs`), a level per
/// zoom from the finest.
fn terrarium(config: &UpstreamConfig, link: Arc<Link>, crs: Crs, cache: &Arc<BlockCache>) -> GeoRaster {
    let levels: Vec<Blocks> = (0..=config.zoom)
        .rev()
        .map(|z| Blocks::new(Arc::new(Terrarium { link: link.clone(), zoom: z, template: config.url.clone() }), cache))
        .collect();
    let res = 2.0 * HALF_WORLD_M / (BLOCK as f64 * (1u64 << config.zoom) as f64);
    let georef = Georef {
        crs: Arc::new(crs),
        x0: -HALF_WORLD_M + 0.5 * res,
        y0: HALF_WORLD_M - 0.5 * res,
        dx: res,
        dy: -res,
        overhang: 0.5,
    };
    GeoRaster::from_levels(levels, georef)
}

/// A WMS over `area` at the configured resolution, with levels halving it
/// until one fits a block.
fn wms(config: &UpstreamConfig, request: WmsUrl, link: Arc<Link>, area: BBox, cache: &Arc<BlockCache>) -> GeoRaster {
    let res = config.resolution_deg;
    let width = ((area.east - area.west) / res).ceil() as usize;
    let height = ((area.north - area.south) / res).ceil() as usize;
    let mut levels = Vec::new();
    for k in 0..=MAX_HALVINGS {
        let (w, h) = (width.div_ceil(1 << k), height.div_ceil(1 << k));
        let level = Wms {
            link: link.clone(),
            request: request.clone(),
            west: area.west,
            north: area.north,
            res: res * (1u64 << k) as f64,
            size: (w, h),
        };
        levels.push(Blocks::new(Arc::new(level), cache));
        if w <= BLOCK && h <= BLOCK {
            break;
        }
    }
    let georef = Georef {
        crs: Arc::new(Crs::wgs84()),
        x0: area.west + 0.5 * res,
        y0: area.north - 0.5 * res,
        dx: res,
        dy: -res,
        overhang: 0.5,
    };
    GeoRaster::from_levels(levels, georef)
}

/// One zoom level of a Terrarium service: a Web Mercator raster of
/// `256·2^z` pixels square whose blocks are its tiles.
struct Terrarium {
    link: Arc<Link>,
    zoom: u32,
    template: String,
}

impl PixelSource for Terrarium {
    fn name(&self) -> &Path {
        Path::new(&self.template)
    }

    fn size(&self) -> (usize, usize) {
        let side = BLOCK << self.zoom;
        (side, side)
    }

    fn bands(&self) -> usize {
        1
    }

    fn block_size(&self) -> (usize, usize) {
        (BLOCK, BLOCK)
    }

    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let url = self
            .template
            .replace("{z}", &self.zoom.to_string())
            .replace("{x}", &bx.to_string())
            .replace("{y}", &by.to_string());
        let Some(body) = self.link.fetch(&url)? else {
            return Ok(vec![Raster::filled(BLOCK, BLOCK, f32::NAN)]);
        };
        let bad = |problem: String| SourceError::Upstream { url: url.clone(), problem };
        let img = image::load_from_memory(&body).map_err(|e| bad(format!("not a PNG tile: {e}")))?.into_rgba8();
        if img.dimensions() != (BLOCK as u32, BLOCK as u32) {
            return Err(bad(format!("tile is {:?}, expected 256×256", img.dimensions())));
        }
        Ok(vec![Raster::from_fn(BLOCK, BLOCK, |x, y| {
            let p = img.get_pixel(x as u32, y as u32).0;
            if p[3] == 0 || p[..3] == [0, 0, 0] {
                f32::NAN
            } else {
                crate::encode::terrarium::height([p[0], p[1], p[2]]) as f32
            }
        })])
    }
}

/// One resolution of a WMS: a lat/lon raster whose blocks are GetMap
/// requests (pixel-is-area boxes, so pixel centres land on the raster's).
struct Wms {
    link: Arc<Link>,
    request: WmsUrl,
    west: f64,
    north: f64,
    res: f64,
    size: (usize, usize),
}

impl PixelSource for Wms {
    fn name(&self) -> &Path {
        Path::new(&self.request.url)
    }

    fn size(&self) -> (usize, usize) {
        self.size
    }

    fn bands(&self) -> usize {
        if self.request.picture { 3 } else { 1 }
    }

    fn block_size(&self) -> (usize, usize) {
        (BLOCK, BLOCK)
    }

    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let b = self.block_window(bx, by)?;
        let west = self.west + b.x as f64 * self.res;
        let north = self.north - b.y as f64 * self.res;
        let (east, south) = (west + b.width as f64 * self.res, north - b.height as f64 * self.res);
        let url = self.request.get_map([west, south, east, north], (b.width, b.height));
        let Some(body) = self.link.fetch(&url)? else {
            return Ok(vec![Raster::filled(b.width, b.height, f32::NAN); self.bands()]);
        };
        let decoded = match self.request.picture {
            true => colours(&body, (b.width, b.height)),
            false => values(&body, (b.width, b.height)).map(|v| vec![v]),
        };
        decoded.map_err(|problem| SourceError::Upstream { url, problem })
    }
}

/// A picture's R, G and B bands, if it is `size` pixels.
fn colours(body: &[u8], (w, h): (usize, usize)) -> Result<Vec<Raster<f32>>, String> {
    let img = image::load_from_memory(body).map_err(|e| format!("not an image: {e}"))?.into_rgba8();
    if img.dimensions() != (w as u32, h as u32) {
        return Err(format!("the image is {}×{} pixels, {w}×{h} were asked for", img.width(), img.height()));
    }
    Ok((0..3).map(|k| Raster::from_fn(w, h, |x, y| f32::from(img.get_pixel(x as u32, y as u32).0[k]))).collect())
}

/// Largest magnitude of a value read from a float32 upstream: beyond it
/// the bytes are no heights, cover or classes (a body of the right size
/// that is something else).
const MAX_VALUE: f32 = 1.0e6;

/// Little-endian float32 values of `size`, the BIL nodata value as NaN.
fn values(body: &[u8], (w, h): (usize, usize)) -> Result<Raster<f32>, String> {
    if body.len() != 4 * w * h {
        return Err(format!("{} bytes, expected {} (application/bil32)", body.len(), 4 * w * h));
    }
    let mut values = Vec::with_capacity(w * h);
    for c in body.chunks_exact(4) {
        let v = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        if v == crate::encode::NODATA_HEIGHT {
            values.push(f32::NAN);
        } else if v.is_finite() && v.abs() <= MAX_VALUE {
            values.push(v);
        } else {
            return Err(format!("a value of {v}: not float32 data (application/bil32)"));
        }
    }
    Raster::from_vec(w, h, values).ok_or_else(|| "short body".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE: &str = "http://up:8080/wms?SERVICE=WMS&REQUEST=GetMap&LAYERS=dem&STYLES=";

    #[test]
    fn a_wms_url_is_checked_and_its_boxes_follow_its_axis_order() {
        let url = |rest: &str| WmsUrl::parse(&format!("{BASE}&{rest}"));
        let lon_lat = url("VERSION=1.3.0&CRS=CRS:84&FORMAT=application/bil32").unwrap();
        assert!(!lon_lat.picture && !lon_lat.lat_first);
        assert!(lon_lat.get_map([10.0, 46.0, 11.0, 47.0], (4, 2)).ends_with("&BBOX=10,46,11,47&WIDTH=4&HEIGHT=2"));
        // WMS 1.3.0 in EPSG:4326 is latitude first; 1.1.1's SRS is not.
        let lat_lon = url("VERSION=1.3.0&CRS=EPSG:4326&FORMAT=image%2Fpng").unwrap();
        assert!(lat_lon.picture && lat_lon.lat_first);
        assert!(lat_lon.get_map([10.0, 46.0, 11.0, 47.0], (4, 2)).contains("&BBOX=46,10,47,11&"));
        assert!(!url("VERSION=1.1.1&SRS=EPSG:4326&FORMAT=application/bil32").unwrap().lat_first);
        for (rest, said) in [
            ("CRS=CRS:84&FORMAT=image/jpeg", "FORMAT=image/jpeg: read are"),
            ("CRS=CRS:84&FORMAT=image/tiff", "FORMAT=image/tiff"),
            ("CRS=CRS:84", "no FORMAT"),
            ("CRS=CRS:84&FORMAT=application/bil32&BBOX=0,0,1,1", "leave BBOX out"),
            ("CRS=CRS:84&FORMAT=application/bil32&width=5", "leave WIDTH out"),
            ("CRS=EPSG:3857&FORMAT=application/bil32", "CRS=EPSG:3857: boxes are asked in degrees"),
            ("CRS=EPSG:4326&FORMAT=application/bil32", "without VERSION"),
            ("FORMAT=application/bil32", "no CRS"),
        ] {
            let e = url(rest).unwrap_err();
            assert!(e.contains(said), "{rest}: {e}");
        }
        for bad in ["ftp://up/wms?FORMAT=image/png&CRS=CRS:84", "not a url at all", "http:///wms"] {
            assert!(WmsUrl::parse(bad).unwrap_err().starts_with("not "), "{bad}");
        }
    }

    fn png(w: u32, h: u32) -> Vec<u8> {
        let mut out = std::io::Cursor::new(Vec::new());
        image::RgbImage::from_pixel(w, h, image::Rgb([10, 20, 30]))
            .write_to(&mut out, image::ImageFormat::Png)
            .unwrap();
        out.into_inner()
    }

    #[test]
    fn an_upstream_picture_or_grid_of_another_size_or_kind_is_refused() {
        // Regression: a 10×10 PNG for a 12×12 block panicked, a larger one was cropped.
        assert_eq!(colours(&png(12, 12), (12, 12)).unwrap()[2].get(11, 11), 30.0);
        for (w, h) in [(10, 10), (13, 12)] {
            let e = colours(&png(w, h), (12, 12)).unwrap_err();
            assert!(e.contains(&format!("{w}×{h} pixels, 12×12 were asked for")), "{e}");
        }
        let floats = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let grid = values(&floats(&[1.5, -32768.0, 8848.0, -430.0]), (2, 2)).unwrap();
        assert_eq!((grid.get(0, 0), grid.get(1, 0).is_nan(), grid.get(0, 1)), (1.5, true, 8848.0));
        assert!(values(&floats(&[1.5, 2.0e38, 0.0, 0.0]), (2, 2)).unwrap_err().contains("not float32 data"));
        assert!(values(&floats(&[1.5, f32::NAN, 0.0, 0.0]), (2, 2)).is_err());
        assert!(values(&floats(&[1.5]), (2, 2)).unwrap_err().contains("4 bytes, expected 16"));
    }
}
