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
            Ok(wms(config, link, area, cache))
        }
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
fn wms(config: &UpstreamConfig, link: Arc<Link>, area: BBox, cache: &Arc<BlockCache>) -> GeoRaster {
    let res = config.resolution_deg;
    let width = ((area.east - area.west) / res).ceil() as usize;
    let height = ((area.north - area.south) / res).ceil() as usize;
    let mut levels = Vec::new();
    for k in 0..=21 {
        let (w, h) = (width.div_ceil(1 << k), height.div_ceil(1 << k));
        let level = Wms {
            link: link.clone(),
            url: config.url.clone(),
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
    url: String,
    west: f64,
    north: f64,
    res: f64,
    size: (usize, usize),
}

impl PixelSource for Wms {
    fn name(&self) -> &Path {
        Path::new(&self.url)
    }

    fn size(&self) -> (usize, usize) {
        self.size
    }

    fn bands(&self) -> usize {
        if self.url.to_ascii_lowercase().contains("format=image%2fpng")
            || self.url.to_ascii_lowercase().contains("format=image/png")
        {
            3
        } else {
            1
        }
    }

    fn block_size(&self) -> (usize, usize) {
        (BLOCK, BLOCK)
    }

    fn read_block(&self, bx: usize, by: usize) -> Result<Vec<Raster<f32>>, SourceError> {
        let b = self.block_window(bx, by)?;
        let west = self.west + b.x as f64 * self.res;
        let north = self.north - b.y as f64 * self.res;
        let (east, south) = (west + b.width as f64 * self.res, north - b.height as f64 * self.res);
        let sep = if self.url.contains('?') { '&' } else { '?' };
        let url = format!("{}{sep}BBOX={west},{south},{east},{north}&WIDTH={}&HEIGHT={}", self.url, b.width, b.height);
        let Some(body) = self.link.fetch(&url)? else {
            return Ok(vec![Raster::filled(b.width, b.height, f32::NAN); self.bands()]);
        };
        let bad = |problem: String| SourceError::Upstream { url: url.clone(), problem };
        if self.bands() == 3 {
            let img = image::load_from_memory(&body).map_err(|e| bad(format!("not an image: {e}")))?.into_rgba8();
            return Ok((0..3)
                .map(|k| Raster::from_fn(b.width, b.height, |x, y| f32::from(img.get_pixel(x as u32, y as u32).0[k])))
                .collect());
        }
        if body.len() != 4 * b.width * b.height {
            return Err(bad(format!("{} bytes, expected {} (application/bil32)", body.len(), 4 * b.width * b.height)));
        }
        let values = body
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .map(|v| if v == crate::encode::NODATA_HEIGHT { f32::NAN } else { v });
        Ok(vec![Raster::from_vec(b.width, b.height, values.collect()).ok_or_else(|| bad("short body".into()))?])
    }
}
