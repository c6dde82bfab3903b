//! Upstream sources: a DEM or a map read from another server over HTTP — an
//! XYZ Terrarium tile service, or a WMS (another `sylva serve`, MapServer,
//! GeoServer) — block by block through the block cache (dissertation 6.5: the
//! server is a proxy in front of the data).
//!
//! Each request has a timeout and is retried a bounded number of times with
//! exponential backoff; after repeated failures a circuit breaker fails
//! requests at once for a cool-down, so a dead upstream costs no waiting.
//! Overviews are the upstream's own coarser zoom levels or resolutions.

use super::{BLOCK, BlockCache, Blocks, Crs, GeoRaster, Georef, PixelSource, SourceError};
use crate::config::{UpstreamConfig, UpstreamService};
use crate::grid::mercator::HALF_WORLD_M;
use crate::raster::Raster;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Largest upstream response read, bytes (a 256² float32 block is 256 KiB).
const MAX_RESPONSE_BYTES: u64 = 16 << 20;

/// Opens an upstream as a georeferenced source with native overviews.
pub fn open(config: &UpstreamConfig, cache: &Arc<BlockCache>) -> Result<GeoRaster, SourceError> {
    let name = PathBuf::from(&config.url);
    let bad = |problem: String| SourceError::Malformed { path: name.clone(), problem };
    let link = Arc::new(Link::new(config));
    match config.service {
        UpstreamService::Terrarium => {
            if !(config.url.contains("{z}") && config.url.contains("{x}") && config.url.contains("{y}"))
                || config.zoom > 22
            {
                return Err(bad("a Terrarium template needs {z}, {x} and {y}, and zoom ≤ 22".into()));
            }
            let crs = Arc::new(Crs::from_epsg(3857).map_err(|source| SourceError::Crs { path: name.clone(), source })?);
            let levels: Vec<Blocks> = (0..=config.zoom)
                .rev()
                .map(|z| {
                    Blocks::new(
                        Arc::new(Terrarium { link: link.clone(), zoom: z, template: config.url.clone() }),
                        cache,
                    )
                })
                .collect();
            let res = 2.0 * HALF_WORLD_M / (BLOCK as f64 * (1u64 << config.zoom) as f64);
            let georef = Georef {
                crs,
                x0: -HALF_WORLD_M + 0.5 * res,
                y0: HALF_WORLD_M - 0.5 * res,
                dx: res,
                dy: -res,
                overhang: 0.5,
            };
            Ok(GeoRaster::from_levels(levels, georef))
        }
        UpstreamService::Wms => {
            let area = config.bbox().map_err(bad)?;
            let res = config.resolution_deg;
            if !(res > 0.0 && res.is_finite()) {
                return Err(bad(format!("resolution_deg {res} must be positive")));
            }
            let width = ((area.east - area.west) / res).ceil() as usize;
            let height = ((area.north - area.south) / res).ceil() as usize;
            let mut levels = Vec::new();
            let mut k = 0;
            loop {
                let scale = (1u64 << k) as f64;
                let (w, h) = (width.div_ceil(1 << k), height.div_ceil(1 << k));
                let level = Wms {
                    link: link.clone(),
                    url: config.url.clone(),
                    west: area.west,
                    north: area.north,
                    res: res * scale,
                    size: (w, h),
                };
                levels.push(Blocks::new(Arc::new(level), cache));
                if w <= BLOCK && h <= BLOCK || k > 20 {
                    break;
                }
                k += 1;
            }
            let georef = Georef {
                crs: Arc::new(Crs::wgs84()),
                x0: area.west + 0.5 * res,
                y0: area.north - 0.5 * res,
                dx: res,
                dy: -res,
                overhang: 0.5,
            };
            Ok(GeoRaster::from_levels(levels, georef))
        }
    }
}

/// HTTP with timeouts, retries and a circuit breaker, shared by the levels of
/// one upstream.
struct Link {
    agent: ureq::Agent,
    retries: u32,
    backoff: Duration,
    threshold: u32,
    cooldown: Duration,
    failures: AtomicU32,
    open_until: Mutex<Option<Instant>>,
}

impl Link {
    fn new(c: &UpstreamConfig) -> Link {
        let agent = ureq::Agent::config_builder()
            .timeout_global(Some(Duration::from_millis(c.timeout_ms.max(1))))
            .http_status_as_error(false)
            .build()
            .into();
        Link {
            agent,
            retries: c.retries,
            backoff: Duration::from_millis(c.backoff_ms),
            threshold: c.breaker_failures.max(1),
            cooldown: Duration::from_secs_f64(c.breaker_cooldown_s.max(0.0)),
            failures: AtomicU32::new(0),
            open_until: Mutex::new(None),
        }
    }

    /// The body at `url`; `None` for 404 (no data there).
    fn fetch(&self, url: &str) -> Result<Option<Vec<u8>>, SourceError> {
        let fail = |problem: String| SourceError::Upstream { url: url.to_string(), problem };
        if let Ok(guard) = self.open_until.lock()
            && let Some(until) = *guard
            && Instant::now() < until
        {
            return Err(fail("circuit breaker open after repeated failures".into()));
        }
        let mut last = String::new();
        for attempt in 0..=self.retries {
            if attempt > 0 {
                std::thread::sleep(self.backoff * 2u32.pow(attempt - 1));
            }
            match self.try_once(url) {
                Ok(body) => {
                    self.failures.store(0, Ordering::Relaxed);
                    return Ok(body);
                }
                Err(e) => last = e,
            }
        }
        if self.failures.fetch_add(1, Ordering::Relaxed) + 1 >= self.threshold
            && let Ok(mut guard) = self.open_until.lock()
        {
            *guard = Some(Instant::now() + self.cooldown);
        }
        Err(fail(format!("{last} (after {} attempts)", self.retries + 1)))
    }

    fn try_once(&self, url: &str) -> Result<Option<Vec<u8>>, String> {
        let mut response = self.agent.get(url).call().map_err(|e| e.to_string())?;
        match response.status().as_u16() {
            200 => {
                let mut body = Vec::new();
                response
                    .body_mut()
                    .as_reader()
                    .take(MAX_RESPONSE_BYTES)
                    .read_to_end(&mut body)
                    .map_err(|e| e.to_string())?;
                Ok(Some(body))
            }
            404 => Ok(None),
            status => Err(format!("HTTP {status}")),
        }
    }
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
