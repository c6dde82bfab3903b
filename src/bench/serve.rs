//! `sylva bench serve` and `sylva bench soak`: the tile server measured as
//! its clients see it, over loopback HTTP, beside the peer servers of
//! `shared/peers` in the same sitting.
//!
//! Latencies use the peers' method (`shared/peers/bench.py`): one client, one
//! request at a time, a new TCP connection per request, timed from connect to
//! the last body byte, on the same Web Mercator tiles. Throughput uses `wrk
//! -t1 -c4` on one cached tile URL. The servers run in this process (one
//! per region), so resident memory is this process's.

use super::table;
use crate::grid::TileId;
use crate::grid::mercator::MercatorBox;
use crate::server::{Bound, ServeOptions};
use anyhow::{Context, Result, anyhow};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// What `sylva bench serve` measures and against whom.
#[derive(Clone, Debug)]
pub struct ServeBench {
    /// Configurations of the three DEMs the peers serve: rmnp, bigtujunga, mt_hood.
    pub configs: [PathBuf; 3],
    /// MapServer's WMS endpoint (`shared/peers/run_mapserver.sh`).
    pub mapserver: String,
    /// MapProxy's base URL (`shared/peers/run_mapproxy.sh`).
    pub mapproxy: String,
    /// Warm requests per latency run.
    pub n: usize,
    /// Uncached tiles requested per level, at most.
    pub uncached: usize,
    /// Seconds of each `wrk` run.
    pub wrk_seconds: u32,
}

/// The peers' DEMs: name, WMS layer of MapServer, centre and zoom of the
/// 512-pixel tiles they are measured on (`shared/peers/tiles.py`).
const PEER_DEMS: [(&str, f64, f64, u32); 3] =
    [("rmnp", -105.7035, 40.3564, 11), ("bigtujunga", -118.1492, 34.3203, 12), ("mt_hood", -121.6942, 45.3740, 12)];

/// The 2 × 2 block of XYZ tiles nearest a DEM's centre, as `tiles.py` picks them.
fn peer_tiles(lon: f64, lat: f64, z: u32) -> Vec<(u32, u64, u64)> {
    let n = f64::from(1u32 << z);
    let fx = (lon + 180.0) / 360.0 * n;
    let fy = (1.0 - lat.to_radians().tan().asinh() / std::f64::consts::PI) / 2.0 * n;
    let (x0, y0) = (fx.round() as u64 - 1, fy.round() as u64 - 1);
    (0..4).map(|i| (z, x0 + i % 2, y0 + i / 2)).collect()
}

/// A GetMap of one XYZ tile's box, 512² BIL16, at `endpoint` (ending in `?`).
fn get_map_url(endpoint: &str, layer: &str, (z, x, y): (u32, u64, u64)) -> Result<String> {
    let b = MercatorBox::of_tile(z, x, y)?;
    Ok(format!(
        "{endpoint}SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS={layer}&STYLES=&CRS=EPSG%3A3857&BBOX={:?}%2C{:?}%2C{:?}%2C{:?}&WIDTH=512&HEIGHT=512&FORMAT=application%2Fbil16",
        b.west, b.south, b.east, b.north
    ))
}

/// One GET over a fresh connection: status, body bytes, connect-to-last-byte time.
pub fn fetch(url: &str) -> Result<(u16, usize, Duration)> {
    let rest = url.strip_prefix("http://").ok_or_else(|| anyhow!("{url}: only http:// URLs"))?;
    let (host, path) = rest.split_at(rest.find('/').unwrap_or(rest.len()));
    let start = Instant::now();
    let mut stream = TcpStream::connect(host).with_context(|| format!("connect {host}"))?;
    stream.set_read_timeout(Some(Duration::from_secs(60)))?;
    write!(stream, "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n")?;
    let mut all = Vec::new();
    stream.read_to_end(&mut all)?;
    let took = start.elapsed();
    let head_end = all.windows(4).position(|w| w == b"\r\n\r\n").ok_or_else(|| anyhow!("{url}: no HTTP header"))?;
    let status =
        std::str::from_utf8(&all[..head_end])?.split_whitespace().nth(1).and_then(|s| s.parse().ok()).unwrap_or(0);
    Ok((status, all.len() - head_end - 4, took))
}

/// Latency percentiles of a run, ms, and the share of non-200 answers.
struct Latency {
    ms: Vec<f64>,
    bad: usize,
    bytes: usize,
}

impl Latency {
    fn measure(urls: &[String], n: usize) -> Result<Latency> {
        let mut out = Latency { ms: Vec::with_capacity(n), bad: 0, bytes: 0 };
        for i in 0..n {
            let (status, bytes, took) = fetch(&urls[i % urls.len()])?;
            out.ms.push(took.as_secs_f64() * 1e3);
            out.bad += usize::from(status != 200);
            out.bytes = bytes;
        }
        out.ms.sort_by(f64::total_cmp);
        Ok(out)
    }

    fn pct(&self, p: f64) -> f64 {
        percentile(&self.ms, p)
    }

    fn row(&self, label: &str) -> Vec<String> {
        vec![
            label.to_string(),
            self.ms.len().to_string(),
            format!("{:.2}", self.pct(50.0)),
            format!("{:.2}", self.pct(90.0)),
            format!("{:.2}", self.pct(99.0)),
            self.bytes.to_string(),
            self.bad.to_string(),
        ]
    }
}

/// Linear-interpolated percentile of sorted values.
fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let k = (sorted.len() - 1) as f64 * p / 100.0;
    let (f, c) = (k.floor() as usize, (k.ceil() as usize).min(sorted.len() - 1));
    sorted[f] + (sorted[c] - sorted[f]) * (k - k.floor())
}

/// Servers running in this process, on loopback ports.
struct Servers {
    runtime: tokio::runtime::Runtime,
    bases: Vec<String>,
    caches: Vec<PathBuf>,
    states: Vec<std::sync::Arc<crate::server::AppState>>,
}

impl Servers {
    /// One server per configuration (`None`: the demo region).
    fn start(configs: &[Option<&Path>]) -> Result<Servers> {
        let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
        let mut bases = Vec::new();
        let mut caches = Vec::new();
        let mut states = Vec::new();
        for (i, config) in configs.iter().enumerate() {
            let cache = std::env::temp_dir().join(format!("sylva-bench-serve-{}-{i}", std::process::id()));
            let _ = std::fs::remove_dir_all(&cache);
            let options = ServeOptions { bind: Some("127.0.0.1:0".into()), cache_dir: Some(cache.clone()) };
            let name = config.map_or("<demo>".into(), |c| c.display().to_string());
            let bound: Bound = runtime.block_on(crate::server::bind(*config, options)).context(name)?;
            bases.push(bound.base_url()?);
            caches.push(cache);
            states.push(bound.state.clone());
            runtime.spawn(bound.run(std::future::pending()));
        }
        Ok(Servers { runtime, bases, caches, states })
    }
}

impl Drop for Servers {
    fn drop(&mut self) {
        for c in &self.caches {
            let _ = std::fs::remove_dir_all(c);
        }
    }
}

/// `wrk -t1 -c4` on one URL: requests per second and p50 / p99 latency, ms.
fn wrk(url: &str, seconds: u32) -> Result<(f64, f64, f64)> {
    let out = Command::new("wrk")
        .args(["-t1", "-c4", &format!("-d{seconds}s"), "--timeout", "10s", "--latency", url])
        .output()
        .context("wrk (apt-get install wrk)")?;
    let text = String::from_utf8_lossy(&out.stdout);
    if text.contains("Non-2xx") {
        return Err(anyhow!("wrk saw non-2xx answers from {url}"));
    }
    let rate = text.lines().find_map(|l| l.strip_prefix("Requests/sec:")).and_then(|v| v.trim().parse().ok());
    let latency = |p: &str| text.lines().find_map(|l| l.trim().strip_prefix(p)).and_then(|v| wrk_ms(v.trim()));
    match (rate, latency("50%"), latency("99%")) {
        (Some(r), Some(p50), Some(p99)) => Ok((r, p50, p99)),
        _ => Err(anyhow!("cannot read wrk's output:\n{text}")),
    }
}

/// `1.23ms`, `456.00us`, `1.02s` → milliseconds.
fn wrk_ms(v: &str) -> Option<f64> {
    let (number, scale) = if let Some(n) = v.strip_suffix("us") {
        (n, 1e-3)
    } else if let Some(n) = v.strip_suffix("ms") {
        (n, 1.0)
    } else {
        (v.strip_suffix('s')?, 1e3)
    };
    number.parse::<f64>().ok().map(|x| x * scale)
}

/// Is anything answering at `url`?
fn reachable(url: &str) -> bool {
    fetch(url).is_ok_and(|(status, _, _)| status == 200)
}

/// Runs the benchmark and returns its report.
pub fn report(b: &ServeBench) -> Result<String> {
    let servers = Servers::start(&b.configs.each_ref().map(|c| Some(c.as_path())))?;
    let mut out =
        vec![format!("sylva bench serve — {} cores, servers in-process on loopback\n", rayon::current_num_threads())];
    out.push(get_map_section(b, &servers)?);
    let (uncached, tile_url) = uncached_section(b, &servers.bases[0], servers.states[0].region())?;
    out.push(uncached);
    out.push(cached_section(b, &tile_url));
    let (rss, peak) = super::rss_mib();
    out.push(format!("resident memory after the run: {rss:.0} MiB (peak {peak:.0} MiB), three regions served\n"));
    Ok(out.join("\n"))
}

/// WMS GetMap 512² BIL16 of the DEM on the peers' 12 tiles: Sylva and MapServer.
fn get_map_section(b: &ServeBench, servers: &Servers) -> Result<String> {
    let mut sylva = Vec::new();
    let mut mapserver = Vec::new();
    for ((name, lon, lat, z), base) in PEER_DEMS.iter().zip(&servers.bases) {
        for t in peer_tiles(*lon, *lat, *z) {
            sylva.push(get_map_url(&format!("{base}/wms?"), "dem", t)?);
            mapserver.push(get_map_url(&b.mapserver, name, t)?);
        }
    }
    let mut rows = Vec::new();
    let mut medians = Vec::new();
    for (label, urls) in [("sylva", &sylva), ("mapserver", &mapserver)] {
        if label == "mapserver"
            && !reachable(&format!("{}SERVICE=WMS&REQUEST=GetCapabilities&VERSION=1.3.0", b.mapserver))
        {
            rows.push(vec![format!("{label}: not running at {}", b.mapserver)]);
            continue;
        }
        rows.push(Latency::measure(urls, urls.len())?.row(&format!("{label} cold (first touch)")));
        for run in 1..=2 {
            let warm = Latency::measure(urls, b.n)?;
            rows.push(warm.row(&format!("{label} warm (run {run})")));
            medians.push((label, warm.pct(50.0)));
        }
    }
    let ratio = ratio_line(&medians, "mapserver", "sylva", "MapServer's p50 / Sylva's p50");
    Ok(format!(
        "WMS GetMap 512² application/bil16, layer dem, 12 Web Mercator tiles of rmnp, bigtujunga, mt_hood (ms)\n{}\n{ratio}\n",
        table(&["server", "n", "p50", "p90", "p99", "bytes", "non-200"], &rows)
    ))
}

/// Mean of the medians of `over` divided by the mean of those of `under`.
fn ratio_line(medians: &[(&str, f64)], over: &str, under: &str, what: &str) -> String {
    let mean = |who: &str| {
        let v: Vec<f64> = medians.iter().filter(|(l, _)| *l == who).map(|(_, m)| *m).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    match (mean(over), mean(under)) {
        (Some(a), Some(b)) => format!("ratio ({what}): {:.2}×", a / b),
        _ => format!("ratio ({what}): not measured"),
    }
}

/// Levels of the uncached tiles: rmnp's DEM pixels are ~230 m, its map's
/// ~130 m; level 8 samples every ~60 m, level 11 every ~7 m (where the
/// canopy proxy shows single crowns).
const UNCACHED_LEVELS: [u32; 4] = [8, 9, 10, 11];

/// Uncached 513² `cem` World Wind tiles of the first region per level,
/// nearest its centre first, as `.bil` (and `.png` on one level); returns the
/// section and a cached tile's URL (without extension).
fn uncached_section(b: &ServeBench, base: &str, region: &crate::region::Region) -> Result<(String, String)> {
    let mut rows = Vec::new();
    let mut first = None;
    for (level, ext) in UNCACHED_LEVELS.iter().map(|&l| (l, "bil")).chain([(10, "png")]) {
        let tiles = nearest_tiles(region, level, b.uncached);
        let Some(&nearest) = tiles.first() else { continue };
        first = first.or(Some(nearest));
        let urls: Vec<String> =
            tiles.iter().map(|t| format!("{base}/tiles/cem/{}/{}/{}_{}.{ext}", t.level, t.row, t.row, t.col)).collect();
        let spacing = region.tiles.tile_samples(nearest, 0).spacing_m();
        rows.push(Latency::measure(&urls, urls.len())?.row(&format!("level {level} ({spacing:.0} m) .{ext}")));
    }
    let section = format!(
        "Uncached 513² cem World Wind tiles of {}, each requested once, nearest the centre first (ms)\n{}\n",
        region.name,
        table(&["tiles", "n", "p50", "p90", "p99", "bytes", "non-200"], &rows)
    );
    let t = first.ok_or_else(|| anyhow!("{}: no tiles", region.name))?;
    Ok((section, format!("{base}/tiles/cem/{}/{}/{}_{}", t.level, t.row, t.row, t.col)))
}

/// Up to `n` tiles of `level` inside the region, nearest its centre first.
fn nearest_tiles(region: &crate::region::Region, level: u32, n: usize) -> Vec<TileId> {
    let b = region.bounds;
    let (cx, cy) = (0.5 * (b.west + b.east), 0.5 * (b.south + b.north));
    let centre = region.tiles.tile_containing(cx, cy, level);
    let mut all = region.tiles.tiles_over(&b, level);
    let d = |t: &TileId| (t.row as i64 - centre.row as i64).pow(2) + (t.col as i64 - centre.col as i64).pow(2);
    all.sort_by_key(d);
    all.truncate(n);
    all
}

/// Cached tiles under `wrk -t1 -c4`: Sylva's `.bil` and `.png`, MapProxy's
/// 512² PNG16.
fn cached_section(b: &ServeBench, tile_url: &str) -> String {
    let mut rows = Vec::new();
    let mut rates = Vec::new();
    // The tile the peers' wrk run uses (`bench.py urls`: the first of bigtujunga).
    let (name, lon, lat, z) = PEER_DEMS[1];
    let (z, x, y) = peer_tiles(lon, lat, z)[0];
    let mapproxy = format!("{}/wmts/{name}/webmercator_512/{z}/{x}/{y}.png", b.mapproxy);
    let targets = [
        ("sylva .bil", format!("{tile_url}.bil")),
        ("sylva .png", format!("{tile_url}.png")),
        ("mapproxy png16 512", mapproxy),
    ];
    for (label, url) in targets {
        if !reachable(&url) {
            rows.push(vec![label.to_string(), format!("not reachable: {url}")]);
            continue;
        }
        let bytes = fetch(&url).map_or(0, |(_, n, _)| n);
        match wrk(&url, b.wrk_seconds) {
            Ok((rate, p50, p99)) => {
                rates.push((if label.starts_with("sylva") { label } else { "mapproxy" }, rate));
                rows.push(vec![
                    label.to_string(),
                    format!("{rate:.0}"),
                    format!("{p50:.2}"),
                    format!("{p99:.2}"),
                    bytes.to_string(),
                ]);
            }
            Err(e) => rows.push(vec![label.to_string(), e.to_string()]),
        }
    }
    let ratio = ["sylva .bil", "sylva .png"]
        .map(|s| ratio_line(&rates, s, "mapproxy", &format!("{s} req/s / MapProxy's")))
        .join("\n");
    format!(
        "Cached tile, wrk -t1 -c4 -d{}s on one URL\n{}\n{ratio}\n",
        b.wrk_seconds,
        table(&["tile", "req/s", "p50 ms", "p99 ms", "bytes"], &rows)
    )
}

/// `sylva bench soak`: `minutes` of mixed load on one server (two clients:
/// new tiles over six levels in three layers and two encodings, WMS GetMaps
/// of random boxes and sizes, and a few popular cached tiles), printing the
/// resident memory every `every_s` seconds.
pub fn soak(config: Option<&Path>, minutes: f64, every_s: f64) -> Result<String> {
    let servers = Servers::start(&[config])?;
    let region = servers.states[0].region();
    let base = servers.bases[0].clone();
    let deadline = Instant::now() + Duration::from_secs_f64(minutes * 60.0);
    let done = std::sync::atomic::AtomicU64::new(0);
    let failed = std::sync::atomic::AtomicU64::new(0);
    let mut rows = Vec::new();
    std::thread::scope(|s| {
        for client in 0..2i64 {
            let (base, done, failed) = (&base, &done, &failed);
            s.spawn(move || {
                let mut rng = Draws { client, k: 0 };
                while Instant::now() < deadline {
                    let url = soak_request(region, base, &mut rng);
                    match fetch(&url) {
                        Ok((200 | 404, _, _)) => done.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
                        _ => failed.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
                    };
                }
            });
        }
        let start = Instant::now();
        let state = &servers.states[0];
        let reading = || {
            let (rss, peak) = super::rss_mib();
            let mib = |bytes: u64| format!("{:.0}", bytes as f64 / (1 << 20) as f64);
            let n = done.load(std::sync::atomic::Ordering::Relaxed);
            let tiles = servers.runtime.block_on(state.tiles.memory_bytes());
            let blocks = state.region().cache.bytes();
            vec![
                format!("{:.0}", start.elapsed().as_secs_f64()),
                format!("{rss:.0}"),
                format!("{peak:.0}"),
                mib(blocks),
                mib(tiles),
                n.to_string(),
            ]
        };
        loop {
            rows.push(reading());
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            std::thread::sleep(Duration::from_secs_f64(every_s).min(left));
        }
    });
    let failed = failed.into_inner();
    Ok(format!(
        "sylva bench soak — {}, {minutes} min, 2 clients; resident memory, its peak, the block cache and the tile memory cache (MiB)\n{}\nrequests that failed (not 200/404): {failed}\n",
        region.name,
        table(&["s", "rss", "peak", "blocks", "tiles", "requests"], &rows)
    ))
}

/// One request of the soak's mix.
fn soak_request(region: &crate::region::Region, base: &str, rng: &mut Draws) -> String {
    let b = region.bounds;
    let (w, h) = (b.east - b.west, b.north - b.south);
    // The coarsest level whose tiles are smaller than the region, and five finer.
    let top = (0..=crate::grid::TileGrid::MAX_LEVEL).find(|&l| region.tiles.tile_delta_deg(l) < w.max(h)).unwrap_or(0);
    match rng.below(10) {
        0..=3 => {
            let level = top + rng.below(6) as u32;
            let t = region.tiles.tile_containing(b.west + w * rng.unit(), b.south + h * rng.unit(), level);
            let (layer, ext) = [("cem", "bil"), ("cem", "png"), ("dem", "bil"), ("relief", "png"), ("canopy", "bil32")]
                [rng.below(5) as usize];
            format!("{base}/tiles/{layer}/{}/{}/{}_{}.{ext}", t.level, t.row, t.row, t.col)
        }
        4..=6 => {
            let (x0, y0) = (b.west + w * rng.unit(), b.south + h * rng.unit());
            let size = 0.05 + 0.5 * rng.unit();
            let (px, py) = (64 + rng.below(960), 64 + rng.below(960));
            let (layer, format) =
                [("dem", "application/bil16"), ("cem", "image/tiff"), ("relief", "image/png"), ("cover", "image/png")]
                    [rng.below(4) as usize];
            format!(
                "{base}/wms?SERVICE=WMS&VERSION=1.1.1&REQUEST=GetMap&LAYERS={layer}&STYLES=&SRS=EPSG:4326&BBOX={x0},{y0},{},{}&WIDTH={px}&HEIGHT={py}&FORMAT={format}",
                x0 + w * size,
                y0 + h * size
            )
        }
        _ => {
            let t = region.tiles.tile_containing(
                b.west + w * (0.3 + 0.1 * rng.below(4) as f64),
                b.south + 0.5 * h,
                top + 3,
            );
            format!("{base}/tiles/cem/{}/{}/{}_{}.bil", t.level, t.row, t.row, t.col)
        }
    }
}

/// Pseudo-random draws for the load mix: hashes of a counter, one stream per client.
struct Draws {
    client: i64,
    k: i64,
}

impl Draws {
    fn next(&mut self) -> u64 {
        self.k += 1;
        crate::noise::hash2(self.client, self.k, 0x50A4_D3A7)
    }

    /// A number in `0..n`.
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }

    /// A number in `[0, 1)`.
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}
