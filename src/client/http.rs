//! Tiles from a `sylva serve` over HTTP (dissertation 6.5: the client in
//! front of the proxy server). The server's `/tiles.json` gives the tiling;
//! each tile is four World Wind requests with the halo — `cem`, `dem` and
//! `surface` as float32 BIL, `colour` as an RGBA PNG — through a [`Link`]
//! (timeouts, retries with backoff, a circuit breaker). A 404 is a tile
//! without data; where every tile request was answered so, the source
//! says which server had none ([`TileSource::why_no_tile`]). The tile
//! store runs fetches on a bounded pool, which bounds the requests in
//! flight. A base that is no http:// or https:// URL is refused at once,
//! never retried.

use super::source::{FetchError, TileSource};
use super::tile::TilePayload;
use crate::encode::NODATA_HEIGHT;
use crate::grid::{BBox, TileGrid, TileId};
use crate::region::Tileset;
use crate::source::link::{Link, LinkSettings};
use std::sync::atomic::{AtomicU64, Ordering};

/// Retries and timeouts of tile requests. A tile is up to ~1.3 MB and is
/// computed on demand: tens of ms warm, but the first tiles of a region
/// wait for its sources to load, and a busy server answers 503 until its
/// pool has room — so a minute per request, and six retries backing off
/// from a quarter second (16 s in all).
const SETTINGS: LinkSettings =
    LinkSettings { timeout_ms: 60_000, retries: 6, backoff_ms: 250, breaker_failures: 5, breaker_cooldown_s: 5.0 };

/// Retries and timeouts of `/tiles.json`, which computes nothing: a server
/// that has not answered it in 10 s is not serving (three tries, 30 s).
const CONNECT: LinkSettings = LinkSettings { timeout_ms: 10_000, retries: 2, ..SETTINGS };

/// A tile server as a tile source.
pub struct HttpSource {
    base: String,
    tileset: Tileset,
    grid: TileGrid,
    link: Link,
    bytes: AtomicU64,
    /// Tile requests answered, and of them those answered 404.
    answered: (AtomicU64, AtomicU64),
}

impl HttpSource {
    /// Connects to the server at `base` (e.g. `http://127.0.0.1:8080`) and
    /// reads its tileset.
    pub fn connect(base: &str) -> Result<HttpSource, super::source::OpenError> {
        let base = server_base(base).map_err(super::source::OpenError::Server)?;
        let url = format!("{base}/tiles.json");
        let bad = |reason: String| super::source::OpenError::Server(format!("{url}: {reason}"));
        let body = Link::new(&CONNECT)
            .fetch(&url)
            .map_err(|e| match e {
                crate::source::SourceError::Upstream { problem, .. } => bad(problem),
                other => bad(other.to_string()),
            })?
            .ok_or_else(|| bad("not found: is it a sylva server?".into()))?;
        let (tileset, grid) = read_tileset(&body).map_err(bad)?;
        let link = Link::new(&SETTINGS);
        let answered = (AtomicU64::new(0), AtomicU64::new(0));
        Ok(HttpSource { base, tileset, grid, link, bytes: AtomicU64::new(body.len() as u64), answered })
    }

    fn get(&self, id: TileId, url: String) -> Result<Option<Vec<u8>>, FetchError> {
        let body =
            self.link.fetch(&url).map_err(|e| FetchError::Http { id, url: url.clone(), reason: e.to_string() })?;
        self.answered.0.fetch_add(1, Ordering::Relaxed);
        match &body {
            Some(b) => self.bytes.fetch_add(b.len() as u64, Ordering::Relaxed),
            None => self.answered.1.fetch_add(1, Ordering::Relaxed),
        };
        Ok(body)
    }

    fn url(&self, layer: &str, id: TileId, ext: &str, halo: usize) -> String {
        format!("{}/tiles/{layer}/{}/{}/{}_{}.{ext}?halo={halo}", self.base, id.level, id.row, id.row, id.col)
    }
}

impl TileSource for HttpSource {
    fn grid(&self) -> TileGrid {
        self.grid
    }

    fn bounds(&self) -> BBox {
        let [west, south, east, north] = self.tileset.bounds;
        BBox { west, south, east, north }
    }

    fn fetch(&self, id: TileId, halo: usize) -> Result<Option<TilePayload>, FetchError> {
        if halo > self.tileset.max_halo {
            return Err(FetchError::Http {
                id,
                url: self.base.clone(),
                reason: format!("halo {halo} is above the server's {}", self.tileset.max_halo),
            });
        }
        let count = (self.grid.samples() as usize + 2 * halo).pow(2);
        let floats = |layer: &str| -> Result<Option<Vec<f32>>, FetchError> {
            let url = self.url(layer, id, "bil32", halo);
            let Some(body) = self.get(id, url.clone())? else { return Ok(None) };
            decode_bil32(&body, count).map(Some).map_err(|reason| FetchError::Http { id, url, reason })
        };
        let (Some(cem), Some(dem), Some(classes)) = (floats("cem")?, floats("dem")?, floats("surface")?) else {
            return Ok(None);
        };
        let url = self.url("colour", id, "png", halo);
        let Some(png) = self.get(id, url.clone())? else { return Ok(None) };
        let colour = decode_rgba(&png, count).map_err(|reason| FetchError::Http { id, url, reason })?;
        let surface = classes.iter().map(|&c| if c.is_nan() { crate::cem::surface::NODATA } else { c as u8 }).collect();
        Ok(Some(TilePayload { id, halo, cem, dem, surface, colour }))
    }

    fn bytes_fetched(&self) -> u64 {
        self.bytes.load(Ordering::Relaxed)
    }

    fn why_no_tile(&self) -> Option<String> {
        let (answered, not_found) = (self.answered.0.load(Ordering::Relaxed), self.answered.1.load(Ordering::Relaxed));
        (answered > 0 && not_found == answered).then(|| {
            format!(
                "the server at {base} had no tile for any request: {answered} requests, all 404 — its /tiles.json \
                 answered, its tiles did not: is {base} the server you meant, and do its sources hold data over its region?",
                base = self.base
            )
        })
    }

    fn describe(&self) -> String {
        format!("{} ({}), {} samples per tile", self.base, self.tileset.name, self.tileset.samples)
    }
}

/// `base` without trailing slashes if it is an http:// or https:// URL
/// with a host and no query; else why not, at once (no request is retried
/// for it).
fn server_base(base: &str) -> Result<String, String> {
    let refused = |why: &str| Err(format!("{base}: {why}; a server is http://HOST[:PORT] or https://HOST[:PORT]"));
    let uri = match base.parse::<ureq::http::Uri>() {
        Ok(uri) => uri,
        Err(_) => return refused("not a URL"),
    };
    // The port as written (`Uri::port` drops one past 65535).
    let authority = uri.authority().map_or("", |a| a.as_str());
    let port = authority.rsplit_once(':').map(|(_, p)| p).filter(|p| p.bytes().all(|b| b.is_ascii_digit()));
    match (uri.scheme_str(), uri.host()) {
        (Some("http" | "https"), _) if uri.query().is_some() => refused("a query has no place in it"),
        (Some("http" | "https"), _) if port.as_ref().is_some_and(|p| p.parse::<u16>().is_err()) => {
            refused(&format!("port {} is not 0 to 65535", port.unwrap_or_default()))
        }
        (Some("http" | "https"), Some(host)) if !host.is_empty() => Ok(base.trim_end_matches('/').to_string()),
        (Some("http" | "https"), _) => refused("no host"),
        (Some(scheme), _) => refused(&format!("the scheme {scheme}:// is not HTTP")),
        (None, _) => refused("no scheme"),
    }
}

/// A server's tileset and its grid, checked: a grid Sylva can tile and
/// bounds that are a box on the globe.
fn read_tileset(body: &[u8]) -> Result<(Tileset, TileGrid), String> {
    let tileset: Tileset = serde_json::from_slice(body).map_err(|e| format!("not a tileset: {e}"))?;
    let grid = TileGrid::new(tileset.level0_delta_deg, tileset.samples).map_err(|e| e.to_string())?;
    let [west, south, east, north] = tileset.bounds;
    BBox { west, south, east, north }.checked().map_err(|e| format!("bounds: {e}"))?;
    Ok((tileset, grid))
}

/// Little-endian float32 samples; the BIL nodata value becomes NaN.
fn decode_bil32(body: &[u8], count: usize) -> Result<Vec<f32>, String> {
    if body.len() != count * 4 {
        return Err(format!("{} bytes, expected {} float32 samples", body.len(), count));
    }
    Ok(body
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .map(|v| if v == NODATA_HEIGHT { f32::NAN } else { v })
        .collect())
}

fn decode_rgba(body: &[u8], count: usize) -> Result<Vec<[u8; 4]>, String> {
    let img = image::load_from_memory(body).map_err(|e| format!("not a PNG: {e}"))?.into_rgba8();
    if (img.width() * img.height()) as usize != count {
        return Err(format!("image is {}×{}, expected {count} pixels", img.width(), img.height()));
    }
    Ok(img.pixels().map(|p| p.0).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tileset(bounds: &str) -> String {
        format!(r#"{{"name": "x", "level0_delta_deg": 36.0, "samples": 513, "bounds": [{bounds}], "max_halo": 64}}"#)
    }

    #[test]
    fn a_tileset_whose_bounds_are_no_box_is_refused() {
        let (t, grid) = read_tileset(tileset("10.0, 46.3, 10.25, 46.45").as_bytes()).unwrap();
        assert_eq!((t.bounds[2], grid.samples()), (10.25, 513));
        for (bounds, needle) in [
            ("10.25, 46.45, 10.0, 46.3", "need west < east"),
            ("10.25, 46.3, 10.0, 46.45", "need west < east"),
            ("10.0, 46.45, 10.25, 46.3", "need -90 ≤ south < north ≤ 90"),
            ("10.0, 46.3, 10.25, 95.0", "need -90 ≤ south < north ≤ 90"),
        ] {
            let e = read_tileset(tileset(bounds).as_bytes()).unwrap_err();
            assert!(e.starts_with("bounds: ") && e.contains(needle), "{bounds}: {e}");
        }
        assert!(read_tileset(b"{}").unwrap_err().contains("not a tileset"));
    }

    #[test]
    fn a_server_that_is_no_http_url_is_refused_at_once() {
        // Regression: these were tried three times, backing off, before
        // "bad uri: unknown scheme".
        for (base, why) in [
            ("ftp://host", "the scheme ftp:// is not HTTP"),
            ("not a url", "not a URL"),
            ("localhost:8080", "no scheme"),
            ("http://", "not a URL"),
            ("http://h:8080?x=1", "a query has no place in it"),
            ("http://127.0.0.1:99999", "port 99999 is not 0 to 65535"),
        ] {
            let start = std::time::Instant::now();
            let Err(e) = HttpSource::connect(base) else { panic!("{base} was taken") };
            let said = e.to_string();
            assert!(said.starts_with(&format!("{base}: {why}; a server is http://HOST")), "{said}");
            assert!(start.elapsed().as_secs_f64() < 0.2, "{base}: refused after {:?}", start.elapsed());
        }
        assert_eq!(server_base("https://tiles.example.org:8443//").as_deref(), Ok("https://tiles.example.org:8443"));
    }
}
