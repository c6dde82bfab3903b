//! Proxy sources: a `sylva serve` whose DEM comes from another `sylva serve`
//! over WMS or Terrarium tiles; upstreams that hang or fail give timely
//! errors, the circuit breaker fails fast, and stale tiles are served when
//! the upstream is gone.

use crate::common::{self, TempDir};
use crate::http::Server;
use std::io::{Read, Write};
use std::net::TcpListener;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use sylva::grid::TileId;

fn demo_tile() -> TileId {
    let b = common::demo().bounds;
    common::demo().tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 11)
}

fn tile_path(t: TileId, ext: &str) -> String {
    format!("/tiles/dem/{}/{}/{}_{}.{ext}", t.level, t.row, t.row, t.col)
}

fn bil32(bytes: &[u8]) -> Vec<f32> {
    bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

/// A configuration whose DEM is read from `upstream` (a `[dem.upstream]`
/// table body), written into `dir`.
fn proxy_config(dir: &TempDir, upstream: &str) -> PathBuf {
    let b = common::demo().bounds;
    let text = format!(
        "name = \"proxy\"\n[dem.upstream]\n{upstream}\nbounds = [{}, {}, {}, {}]\n",
        b.west, b.south, b.east, b.north
    );
    let path = dir.join("proxy.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn wms_upstream(base: &str, extra: &str) -> String {
    format!(
        "service = \"wms\"\nurl = \"{base}/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=dem&STYLES=&CRS=CRS:84&FORMAT=application/bil32\"\nresolution_deg = {}\n{extra}",
        1.0 / 3600.0
    )
}

#[test]
fn a_proxy_serves_the_upstream_dem_over_wms_and_terrarium() {
    let dir = TempDir::new("up-proxy");
    let upstream = Server::start(None, &dir.join("cache-up"));
    let direct = bil32(&upstream.get(&tile_path(demo_tile(), "bil32")).body);
    assert_eq!(direct.len(), 513 * 513);

    // WMS: the upstream answers on the DEM's own pixel centres, so the proxy
    // resamples the same pixels as the upstream does.
    let config = proxy_config(&dir, &wms_upstream(&upstream.base, ""));
    let proxy = Server::start(Some(&config), &dir.join("cache-wms"));
    let reply = proxy.get(&tile_path(demo_tile(), "bil32"));
    assert_eq!(reply.status, 200, "{}", reply.text());
    let via_wms = bil32(&reply.body);
    let worst = direct.iter().zip(&via_wms).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "WMS proxy differs from the upstream by up to {worst} m");
    drop(proxy);

    // Terrarium: 4 mm steps on the upstream's Web Mercator grid at zoom 13
    // (~13 m pixels here), resampled again by the proxy.
    let terrarium =
        format!("service = \"terrarium\"\nurl = \"{}/xyz/dem/{{z}}/{{x}}/{{y}}.png\"\nzoom = 13", upstream.base);
    let config = proxy_config(&dir, &terrarium);
    let proxy = Server::start(Some(&config), &dir.join("cache-xyz"));
    let reply = proxy.get(&tile_path(demo_tile(), "bil32"));
    assert_eq!(reply.status, 200, "{}", reply.text());
    let via_xyz = bil32(&reply.body);
    let rmse =
        (direct.iter().zip(&via_xyz).map(|(a, b)| f64::from(a - b).powi(2)).sum::<f64>() / direct.len() as f64).sqrt();
    assert!(rmse < 0.5, "Terrarium proxy RMSE {rmse} m against the upstream");
}

/// A loopback server that answers every request the same bad way.
fn bad_upstream(behaviour: &'static str) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            std::thread::spawn(move || {
                let mut stream = stream;
                let mut buf = [0u8; 4096];
                let _ = stream.read(&mut buf);
                match behaviour {
                    "hang" => std::thread::sleep(Duration::from_secs(600)),
                    _ => {
                        let body = "upstream exploded";
                        let _ = write!(
                            stream,
                            "HTTP/1.1 500 Internal Server Error\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                            body.len()
                        );
                    }
                }
            });
        }
    });
    base
}

#[test]
fn an_upstream_that_hangs_or_fails_gives_a_timely_exception_and_the_server_stays_up() {
    for behaviour in ["hang", "500"] {
        let dir = TempDir::new(&format!("up-{behaviour}"));
        let settings = "timeout_ms = 300\nretries = 1\nbackoff_ms = 50\nbreaker_failures = 2\nbreaker_cooldown_s = 60";
        let config = proxy_config(&dir, &wms_upstream(&bad_upstream(behaviour), settings));
        let proxy = Server::start(Some(&config), &dir.join("cache"));
        let b = common::demo().bounds;
        let get_map = format!(
            "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=dem&STYLES=&CRS=CRS:84&BBOX={},{},{},{}&WIDTH=64&HEIGHT=64&FORMAT=image/tiff",
            b.west,
            b.south,
            b.west + 0.01,
            b.south + 0.01
        );
        let start = Instant::now();
        let reply = proxy.get(&get_map);
        let took = start.elapsed();
        assert_eq!(reply.status, 502, "{behaviour}: {}", reply.text());
        assert!(reply.text().contains("ServiceExceptionReport"), "{behaviour}: {}", reply.text());
        assert!(took < Duration::from_secs(5), "{behaviour}: answered after {took:?}");
        let said = if behaviour == "hang" { "no answer within 300 ms" } else { "HTTP 500: upstream exploded" };
        assert!(reply.text().contains(said), "{behaviour}: {}", reply.text());
        // Tiles fail the same way; after two failures the breaker answers at once.
        assert_eq!(proxy.get(&tile_path(demo_tile(), "bil")).status, 502, "{behaviour}");
        let start = Instant::now();
        let reply = proxy.get(&tile_path(TileId::new(11, demo_tile().row + 2, demo_tile().col), "bil"));
        assert_eq!(reply.status, 502);
        assert!(reply.text().contains("circuit breaker"), "{behaviour}: {}", reply.text());
        assert!(
            start.elapsed() < Duration::from_millis(250),
            "{behaviour}: the open breaker waited {:?}",
            start.elapsed()
        );
        // A map that asks for in-image exceptions gets one, with the status.
        let picture =
            proxy.get(&get_map.replace("dem", "relief").replace("image/tiff", "image/png&EXCEPTIONS=INIMAGE"));
        assert_eq!((picture.status, picture.header("content-type")), (502, Some("image/png")), "{behaviour}");
        assert_eq!(proxy.get("/health").status, 200, "{behaviour}: still up");
    }
}

#[test]
fn stale_tiles_are_served_when_the_upstream_is_gone() {
    let dir = TempDir::new("up-stale");
    let upstream = Server::start(None, &dir.join("cache-up"));
    // The first fetch computes the upstream's tile cold (seconds in a debug
    // build beside other tests); once it is gone, connections are refused at once.
    let config = proxy_config(&dir, &wms_upstream(&upstream.base, "ttl_s = 1\ntimeout_ms = 10000\nretries = 0"));
    let cache = dir.join("cache-proxy");
    let fresh = {
        let proxy = Server::start(Some(&config), &cache);
        let reply = proxy.get(&tile_path(demo_tile(), "bil32"));
        assert_eq!(reply.status, 200, "{}", reply.text());
        assert!(reply.header("warning").is_none());
        reply.body
    };
    drop(upstream);
    std::thread::sleep(Duration::from_millis(1200));
    // A new proxy on the same cache: nothing in memory, the file is past its
    // time to live, the upstream is gone.
    let proxy = Server::start(Some(&config), &cache);
    let stale = proxy.get(&tile_path(demo_tile(), "bil32"));
    assert_eq!(stale.status, 200, "{}", stale.text());
    assert!(stale.body == fresh);
    assert!(stale.header("warning").is_some_and(|w| w.starts_with("110")), "{:?}", stale.headers);
    assert_eq!(proxy.metric("sylva_tile_cache_total{result=\"stale\"}"), 1.0);
    // A tile never fetched has nothing to fall back on.
    let other = TileId::new(11, demo_tile().row + 1, demo_tile().col);
    assert_eq!(proxy.get(&tile_path(other, "bil32")).status, 502);
}

/// A GetMap over the demo on no tile's grid (computed whole, not from tiles).
fn odd_map(layers: &str) -> String {
    let b = common::demo().bounds;
    let (w, s) = (b.west + 0.013, b.south + 0.017);
    format!(
        "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS={layers}&STYLES=&CRS=CRS:84&BBOX={w},{s},{},{}&WIDTH=37&HEIGHT=29&FORMAT=application/bil32",
        w + 0.011,
        s + 0.007
    )
}

#[test]
fn a_map_is_made_of_stale_source_data_while_the_upstream_is_gone() {
    // Regression: tiles were served stale, but a GetMap on no tile's grid
    // (what QGIS and GDAL ask) was a 502 once the source blocks expired.
    let dir = TempDir::new("up-stale-map");
    let upstream = Server::start(None, &dir.join("cache-up"));
    let config = proxy_config(&dir, &wms_upstream(&upstream.base, "ttl_s = 1\ntimeout_ms = 10000\nretries = 0"));
    let proxy = Server::start(Some(&config), &dir.join("cache-proxy"));
    let fresh = proxy.get(&odd_map("dem"));
    assert_eq!(fresh.status, 200, "{}", fresh.text());
    assert!(fresh.header("warning").is_none());
    drop(upstream);
    std::thread::sleep(Duration::from_millis(1200));
    for layers in ["dem", "cem"] {
        let stale = proxy.get(&odd_map(layers));
        assert_eq!(stale.status, 200, "{layers}: {}", stale.text());
        assert!(stale.header("warning").is_some_and(|w| w.starts_with("110")), "{layers}: {:?}", stale.headers);
        assert_eq!(stale.header("cache-control"), Some("public, max-age=0"), "{layers}: kept nowhere");
        if layers == "dem" {
            assert!(stale.body == fresh.body, "the source's last values");
        }
    }
}

#[test]
fn what_an_upstream_says_of_a_refusal_is_passed_on() {
    let dir = TempDir::new("up-refusal");
    let upstream = Server::start(None, &dir.join("cache-up"));
    let misspelt = wms_upstream(&upstream.base, "").replace("LAYERS=dem", "LAYERS=dme");
    let proxy = Server::start(Some(&proxy_config(&dir, &misspelt)), &dir.join("cache-proxy"));
    let reply = proxy.get(&odd_map("dem"));
    assert_eq!(reply.status, 502, "{}", reply.text());
    assert!(
        reply.text().contains(r#"HTTP 400: LayerNotDefined: layer &quot;dme&quot; is not served"#),
        "{}",
        reply.text()
    );
}

#[test]
fn an_upstream_url_that_cannot_work_is_refused_naming_the_file_and_section() {
    let dir = TempDir::new("up-bad-url");
    let wms = wms_upstream("http://127.0.0.1:9", "");
    for (config, said) in [
        (wms.replace("application/bil32", "image/jpeg"), "[dem.upstream] http://127.0.0.1:9/wms?"),
        (wms.replace("application/bil32", "image/png"), "answers a picture (three bands)"),
        (wms.replace("CRS=CRS:84", "CRS=EPSG:3857"), "CRS=EPSG:3857: boxes are asked in degrees"),
        (wms.replace("http://", "ftp://"), "not an http:// or https:// URL"),
        (format!("{wms}breaker_cooldown_s = inf\n"), "[dem.upstream] breaker_cooldown_s = inf: must be 0 to 86400"),
        (wms.replace(&format!("{}", 1.0 / 3600.0), "1e-12"), "resolution_deg 0.000000000001 is too fine"),
    ] {
        let path = proxy_config(&dir, &config);
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_sylva"))
            .args(["info", "--config"])
            .arg(&path)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(&path.display().to_string()), "{said}: {err}");
        assert!(err.contains(said), "{said}: {err}");
    }
}
