//! The real server on a loopback port, driven over HTTP: WMS capabilities and
//! axis order, World Wind tiles, XYZ tiles, caching, single computation under
//! concurrency, corrupt cache files, bad input, HTTP behaviour, shutdown.

use crate::common::{self, TempDir};
use crate::http::{Server, get};
use sylva::cem::Layer;
use sylva::encode::Format;
use sylva::grid::TileId;

/// A level-11 tile in the middle of the demo region.
fn demo_tile() -> TileId {
    let demo = common::demo();
    let b = demo.bounds;
    demo.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 11)
}

fn bil32(bytes: &[u8]) -> Vec<f32> {
    bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

#[test]
fn capabilities_are_valid_in_both_versions() {
    let dir = TempDir::new("srv-caps");
    let server = Server::start(None, &dir.join("cache"));
    assert!(server.get("/health").text().contains("\"status\":\"ok\""));
    for (version, root) in [("1.3.0", "WMS_Capabilities"), ("1.1.1", "WMT_MS_Capabilities")] {
        let r = server.get(&format!("/wms?service=WMS&request=GetCapabilities&version={version}"));
        assert_eq!(r.status, 200);
        let text = r.text();
        let doc = roxmltree::Document::parse_with_options(
            &text,
            roxmltree::ParsingOptions { allow_dtd: true, ..Default::default() },
        )
        .unwrap();
        assert_eq!(doc.root_element().tag_name().name(), root);
        assert!(text.contains(&format!("{}/wms", server.base)), "OnlineResource names the server");
        for layer in ["dem", "cover", "canopy", "cem", "surface", "relief"] {
            assert!(text.contains(&format!("<Name>{layer}</Name>")), "{layer}");
        }
    }
    // With a trailing slash too (was a bare 404).
    for path in ["/wms/?SERVICE=WMS&REQUEST=GetCapabilities", "/wmts/?SERVICE=WMTS&REQUEST=GetCapabilities"] {
        let r = server.get(path);
        assert!(r.status == 200 && r.text().contains("Capabilities"), "{path}: {}", r.status);
    }
}

#[test]
fn every_legend_url_in_the_capabilities_is_a_picture_of_its_stated_size() {
    let dir = TempDir::new("srv-legends");
    let server = Server::start(None, &dir.join("cache"));
    let mut seen = 0;
    for path in [
        "/wms?SERVICE=WMS&REQUEST=GetCapabilities&VERSION=1.3.0",
        "/wms?SERVICE=WMS&REQUEST=GetCapabilities&VERSION=1.1.1",
        "/wmts?SERVICE=WMTS&REQUEST=GetCapabilities",
    ] {
        let text = server.get(path).text();
        let options = roxmltree::ParsingOptions { allow_dtd: true, ..Default::default() };
        let doc = roxmltree::Document::parse_with_options(&text, options).unwrap();
        let xlink = "http://www.w3.org/1999/xlink";
        for legend in doc.descendants().filter(|n| n.has_tag_name("LegendURL")) {
            // WMS names the URL in a child OnlineResource, WMTS on the element.
            let href = legend
                .attribute((xlink, "href"))
                .or_else(|| legend.children().find_map(|c| c.attribute((xlink, "href"))))
                .unwrap();
            let size = ["width", "height"].map(|a| legend.attribute(a).unwrap().parse::<u32>().unwrap());
            let r = server.get(href.strip_prefix(server.base.as_str()).unwrap());
            assert_eq!((r.status, r.header("content-type")), (200, Some("image/png")), "{href}");
            let img = image::load_from_memory(&r.body).unwrap();
            assert_eq!([img.width(), img.height()], size, "{href}");
            seen += 1;
        }
    }
    assert_eq!(seen, 7 + 7 + 5, "a legend for every WMS layer in both versions and every WMTS layer");
    // A legend of a layer not served is the OGC exception, not a picture.
    let r = server.get("/wms?SERVICE=WMS&REQUEST=GetLegendGraphic&VERSION=1.3.0&FORMAT=image/png&LAYER=trees");
    assert!(r.status == 400 && r.text().contains(r#"code="LayerNotDefined""#), "{}", r.text());
}

#[test]
fn capabilities_without_a_host_header_name_the_port_listened_on() {
    let dir = TempDir::new("srv-nohost");
    let server = Server::start(None, &dir.join("cache"));
    let address = server.base.trim_start_matches("http://");
    let port = address.rsplit_once(':').unwrap().1;
    let r = crate::http::send_raw(address, "GET /wms?SERVICE=WMS&REQUEST=GetCapabilities HTTP/1.0\r\n\r\n");
    assert_eq!(r.status, 200);
    assert!(r.text().contains(&format!("http://localhost:{port}/wms")), "{}", r.text());
}

#[test]
fn the_same_area_in_every_axis_order_gives_identical_bytes() {
    let dir = TempDir::new("srv-axes");
    let server = Server::start(None, &dir.join("cache"));
    let common = "SERVICE=WMS&REQUEST=GetMap&LAYERS=cem&STYLES=&WIDTH=300&HEIGHT=200&FORMAT=application/bil32";
    let a = server.get(&format!("/wms?{common}&VERSION=1.3.0&CRS=EPSG:4326&BBOX=46.33,10.05,46.42,10.2"));
    let b = server.get(&format!("/wms?{common}&VERSION=1.3.0&CRS=CRS:84&BBOX=10.05,46.33,10.2,46.42&"));
    let c =
        server.get(&format!("/wms?{}&VERSION=1.1.1&SRS=EPSG:4326&BBOX=10.05,46.33,10.2,46.42", common.to_lowercase()));
    assert_eq!(a.status, 200, "{}", a.text());
    assert_eq!(a.body.len(), 300 * 200 * 4);
    assert!(a.body == b.body && b.body == c.body);
    assert!(bil32(&a.body).iter().all(|v| (500.0..4000.0).contains(v)));
}

#[test]
fn feature_info_gives_the_values_the_map_shows() {
    let dir = TempDir::new("srv-info");
    let server = Server::start(None, &dir.join("cache"));
    let map = "SERVICE=WMS&VERSION=1.3.0&STYLES=&CRS=CRS:84&BBOX=10.05,46.33,10.2,46.42&WIDTH=300&HEIGHT=200";
    let layers = ["dem", "canopy", "cem", "surface"];
    let maps: Vec<Vec<f32>> = layers
        .iter()
        .map(|l| bil32(&server.get(&format!("/wms?{map}&REQUEST=GetMap&LAYERS={l}&FORMAT=application/bil32")).body))
        .collect();
    // The tallest canopy, and pixels spread over the map.
    let tallest = (0..maps[1].len()).max_by(|&a, &b| maps[1][a].total_cmp(&maps[1][b])).unwrap();
    assert!(maps[1][tallest] > 5.0, "the demo has forest here");
    for k in [tallest, 0, 299, 200 * 300 - 1, 123 * 300 + 45] {
        let (i, j) = (k % 300, k / 300);
        let query = format!(
            "/wms?{map}&REQUEST=GetFeatureInfo&LAYERS=relief&FORMAT=image/png&QUERY_LAYERS=dem,canopy,cem,surface&INFO_FORMAT=application/json&I={i}&J={j}"
        );
        let r = server.get(&query);
        assert_eq!((r.status, r.header("content-type")), (200, Some("application/json")), "{}", r.text());
        let doc: serde_json::Value = serde_json::from_str(&r.text()).unwrap();
        for (n, feature) in doc["features"].as_array().unwrap().iter().enumerate() {
            assert_eq!(feature["id"], layers[n]);
            let value = feature["properties"]["value"].as_f64().unwrap() as f32;
            assert_eq!(value, maps[n][k], "{} at pixel ({i}, {j})", layers[n]);
        }
    }
    // WMS 1.1.1 names the pixel X, Y and reads EPSG:4326 as lon,lat.
    let (i, j) = (tallest % 300, tallest / 300);
    let old =
        format!("/wms?{map}&REQUEST=GetFeatureInfo&LAYERS=relief&FORMAT=image/png&QUERY_LAYERS=canopy&X={i}&Y={j}")
            .replace("VERSION=1.3.0", "VERSION=1.1.1")
            .replace("CRS=CRS:84", "SRS=EPSG:4326");
    let text = server.get(&old).text();
    assert!(text.contains(&format!("canopy = {:.2} m", maps[1][tallest])), "{text}");
    // Web Mercator maps too.
    let mercator =
        "SERVICE=WMS&VERSION=1.3.0&STYLES=&CRS=EPSG:3857&BBOX=1118890,5836000,1141000,5850000&WIDTH=256&HEIGHT=256";
    let cem = bil32(&server.get(&format!("/wms?{mercator}&REQUEST=GetMap&LAYERS=cem&FORMAT=application/bil32")).body);
    let r = server.get(&format!(
        "/wms?{mercator}&REQUEST=GetFeatureInfo&LAYERS=cem&FORMAT=image/png&QUERY_LAYERS=cem&INFO_FORMAT=application/json&I=77&J=190"
    ));
    let doc: serde_json::Value = serde_json::from_str(&r.text()).unwrap();
    assert_eq!(doc["features"][0]["properties"]["value"].as_f64().unwrap() as f32, cem[190 * 256 + 77]);
    // A pixel past the antimeridian is named by its longitude on the globe.
    let east = server.get("/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetFeatureInfo&LAYERS=dem&STYLES=&CRS=CRS:84&BBOX=179.9,0,180.1,1&WIDTH=2&HEIGHT=1&FORMAT=image/png&QUERY_LAYERS=dem&I=1&J=0");
    assert!(east.text().contains("lon -179.95000000"), "{}", east.text());
    let off = server
        .get(&format!("/wms?{map}&REQUEST=GetFeatureInfo&LAYERS=cem&FORMAT=image/png&QUERY_LAYERS=cem&I=300&J=0"));
    assert!(off.status == 400 && off.text().contains("InvalidPoint"), "{}", off.text());
    // Only what the map shows may be queried; the map's format does not
    // matter (GDAL's WMS driver asks for JPEG whatever the layer).
    let info = |query: &str| server.get(&format!("/wms?{map}&REQUEST=GetFeatureInfo&I=5&J=5&{query}"));
    let unshown = info("LAYERS=cem&FORMAT=image/png&QUERY_LAYERS=canopy");
    assert!(unshown.status == 400 && unshown.text().contains("LayerNotDefined"), "{}", unshown.text());
    let jpeg = info("LAYERS=dem&FORMAT=image/jpeg&QUERY_LAYERS=dem");
    assert!(jpeg.status == 200 && jpeg.text().contains("dem = "), "{}", jpeg.text());
}

#[test]
fn browsers_may_read_tiles_from_any_page() {
    let dir = TempDir::new("srv-cors");
    let server = Server::start(None, &dir.join("cache"));
    let t = demo_tile();
    let path = format!("/tiles/cem/{}/{}/{}_{}.bil", t.level, t.row, t.row, t.col);
    let r = server.get_with(&path, &[("Origin", "https://maps.example.org")]);
    assert_eq!(r.status, 200);
    assert_eq!(r.header("access-control-allow-origin"), Some("*"));
    assert!(r.header("access-control-expose-headers").is_some_and(|h| h.contains("x-sylva-scale")));
    // A page that revalidates with If-None-Match asks first (regression: the
    // preflight allowed no headers, so the browser never sent the request).
    let host = server.base.strip_prefix("http://").unwrap();
    let preflight = crate::http::send_raw(
        host,
        &format!(
            "OPTIONS {path} HTTP/1.1\r\nHost: {host}\r\nOrigin: https://maps.example.org\r\nAccess-Control-Request-Method: GET\r\nAccess-Control-Request-Headers: if-none-match\r\nConnection: close\r\n\r\n"
        ),
    );
    assert!(preflight.status < 300, "{}", preflight.status);
    let allowed = preflight.headers.iter().find(|(k, _)| k == "access-control-allow-headers").map(|(_, v)| v.as_str());
    assert!(allowed.is_some_and(|h| h == "*" || h.contains("if-none-match")), "{:?}", preflight.headers);
}

#[test]
fn maps_reaching_past_the_data_keep_their_encoding_and_background() {
    let dir = TempDir::new("srv-background");
    let server = Server::start(None, &dir.join("cache"));
    // The demo region fills the middle of this box; its corners are empty.
    let relief = "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=relief&STYLES=&CRS=CRS:84&BBOX=9.9,46.25,10.4,46.5&WIDTH=100&HEIGHT=50&FORMAT=image/png";
    let picture = |query: &str| {
        let r = server.get(&format!("{relief}{query}"));
        assert_eq!(r.status, 200, "{query}: {}", r.text());
        image::load_from_memory(&r.body).unwrap().into_rgba8()
    };
    let (corner, middle) = ((0, 0), (50, 25));
    let white = picture("");
    assert_eq!(
        white.get_pixel(corner.0, corner.1).0,
        [255, 255, 255, 255],
        "opaque white by default (TRANSPARENT=FALSE)"
    );
    let tinted = picture("&BGCOLOR=0x203040");
    assert_eq!(tinted.get_pixel(corner.0, corner.1).0, [0x20, 0x30, 0x40, 255]);
    let clear = picture("&TRANSPARENT=TRUE");
    assert_eq!(clear.get_pixel(corner.0, corner.1).0[3], 0);
    assert_eq!(clear.get_pixel(middle.0, middle.1).0, tinted.get_pixel(middle.0, middle.1).0, "the data is the same");
    let bad = server.get(&format!("{relief}&BGCOLOR=blue"));
    assert!(bad.status == 400 && bad.text().contains("BGCOLOR"), "{}", bad.text());
    // A data layer wholly outside the region: nodata heights, still 16-bit grey.
    let empty = server.get(
        "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=dem&STYLES=&CRS=CRS:84&BBOX=0,0,1,1&WIDTH=4&HEIGHT=4&FORMAT=image/png",
    );
    let heights = image::load_from_memory(&empty.body).unwrap();
    assert_eq!(heights.color(), image::ColorType::L16);
    assert!(heights.into_luma16().pixels().all(|p| p.0[0] == 0), "code 0 is nodata");
    // With the headers of any map: how its codes decode, an ETag.
    for name in ["x-sylva-offset", "x-sylva-scale", "etag", "cache-control"] {
        assert!(empty.header(name).is_some(), "{name} missing from an empty map");
    }
}

#[test]
fn every_data_layer_has_no_data_where_the_ground_has_none() {
    let dir = TempDir::new("srv-nodata");
    let server = Server::start(None, &dir.join("cache"));
    // The demo region fills the middle of this box; its edges are empty.
    let map = "SERVICE=WMS&VERSION=1.3.0&STYLES=&CRS=CRS:84&BBOX=9.95,46.25,10.3,46.5&WIDTH=70&HEIGHT=50";
    let nodata = |layer: &str, code: f32| -> Vec<bool> {
        let r = server.get(&format!("/wms?{map}&REQUEST=GetMap&LAYERS={layer}&FORMAT=application/bil32"));
        bil32(&r.body).iter().map(|&v| v == code).collect()
    };
    let ground = nodata("dem", -32768.0);
    let empty = ground.iter().filter(|&&n| n).count();
    assert!(empty > 0 && empty < ground.len(), "the box reaches past the region");
    for (layer, code) in [("cover", -32768.0), ("canopy", -32768.0), ("cem", -32768.0), ("surface", 255.0)] {
        assert!(nodata(layer, code) == ground, "{layer} has data where the ground has none, or none where it has");
    }
    let corner = server.get(&format!(
        "/wms?{map}&REQUEST=GetFeatureInfo&LAYERS=dem&FORMAT=image/png&QUERY_LAYERS=dem&INFO_FORMAT=text/plain&I=0&J=0"
    ));
    assert!(corner.text().contains("dem = no data"), "{}", corner.text());
}

#[test]
fn every_layer_is_offered_in_jpeg_on_its_background() {
    let dir = TempDir::new("srv-jpeg");
    let server = Server::start(None, &dir.join("cache"));
    let jpeg = |path: &str| {
        let r = server.get(path);
        assert_eq!((r.status, r.header("content-type")), (200, Some("image/jpeg")), "{path}: {}", r.text());
        image::load_from_memory_with_format(&r.body, image::ImageFormat::Jpeg).unwrap().into_rgb8()
    };
    let relief = "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=relief&STYLES=&CRS=CRS:84&BBOX=9.9,46.25,10.4,46.5&WIDTH=100&HEIGHT=50";
    let png = server.get(&format!("{relief}&FORMAT=image/png"));
    let png = image::load_from_memory(&png.body).unwrap().into_rgb8();
    let on_white = jpeg(&format!("{relief}&FORMAT=image/jpeg"));
    let near = |a: [u8; 3], b: [u8; 3], by: u8| a.iter().zip(b).all(|(x, y)| x.abs_diff(y) <= by);
    assert!(near(on_white.get_pixel(0, 0).0, [255, 255, 255], 3), "no data: white");
    let tinted = jpeg(&format!("{relief}&FORMAT=image/jpeg&BGCOLOR=0x203040&TRANSPARENT=TRUE"));
    assert!(near(tinted.get_pixel(0, 0).0, [0x20, 0x30, 0x40], 3), "JPEG lies on BGCOLOR even if transparent is asked");
    // The data is the PNG's, within JPEG's loss: mean difference of a few levels.
    let (x0, y0, x1, y1) = (35, 15, 65, 35);
    let diff: u32 = (y0..y1)
        .flat_map(|y| (x0..x1).map(move |x| (x, y)))
        .map(|(x, y)| {
            (0..3).map(|c| u32::from(png.get_pixel(x, y).0[c].abs_diff(on_white.get_pixel(x, y).0[c]))).sum::<u32>()
        })
        .sum();
    let mean = f64::from(diff) / f64::from(3 * (x1 - x0) * (y1 - y0));
    assert!(mean < 8.0, "mean difference from the PNG {mean:.1}");
    let t = demo_tile();
    assert_eq!(jpeg(&format!("/tiles/relief/{}/{}/{}_{}.jpg", t.level, t.row, t.row, t.col)).dimensions(), (513, 513));
    let trees = format!("{relief}&FORMAT=image/jpeg&EXCEPTIONS=INIMAGE").replace("LAYERS=relief", "LAYERS=trees");
    assert_eq!(jpeg(&trees).dimensions(), (100, 50), "an in-image exception in JPEG");
    // A data layer in JPEG (GDAL's WMS driver asks for it unless told
    // otherwise) is a picture of it: heights shaded grey, classes in
    // colour, no data on white; by tile too.
    let dem = jpeg(&format!("{relief}&FORMAT=image/jpeg").replace("LAYERS=relief", "LAYERS=dem"));
    assert!(near(dem.get_pixel(0, 0).0, [255, 255, 255], 3), "no data: white");
    let inside: Vec<[u8; 3]> =
        (x0..x1).flat_map(|x| (y0..y1).map(move |y| (x, y))).map(|(x, y)| dem.get_pixel(x, y).0).collect();
    assert!(inside.iter().all(|p| p[0].abs_diff(p[1]) <= 3 && p[1].abs_diff(p[2]) <= 3), "heights are grey");
    let (lo, hi) = inside.iter().fold((255, 0), |(lo, hi), p| (p[0].min(lo), p[0].max(hi)));
    assert!(hi - lo > 60, "shaded slopes: grey from {lo} to {hi}");
    let surface = jpeg(&format!("{relief}&FORMAT=image/jpeg").replace("LAYERS=relief", "LAYERS=surface"));
    assert!(
        (x0..x1).any(|x| {
            let [r, g, b] = surface.get_pixel(x, 25).0;
            g > r + 20 && g > b
        }),
        "forest is green"
    );
    let tile = format!("/tiles/cem/{}/{}/{}_{}.jpg", t.level, t.row, t.row, t.col);
    assert_eq!(jpeg(&tile).dimensions(), (513, 513));
}

#[test]
fn world_wind_tiles_have_n_squared_samples_and_neighbours_share_edges() {
    let dir = TempDir::new("srv-ww");
    let server = Server::start(None, &dir.join("cache"));
    let t = demo_tile();
    let n = 513usize;
    let tile = |row: u64, col: u64, ext: &str| server.get(&format!("/tiles/cem/{}/{row}/{row}_{col}.{ext}", t.level));
    let bil16 = tile(t.row, t.col, "bil");
    assert_eq!((bil16.status, bil16.body.len()), (200, n * n * 2));
    let (sw, se, nw) = (
        bil32(&tile(t.row, t.col, "bil32").body),
        bil32(&tile(t.row, t.col + 1, "bil32").body),
        bil32(&tile(t.row + 1, t.col, "bil32").body),
    );
    for i in 0..n {
        assert_eq!(sw[i * n + n - 1].to_bits(), se[i * n].to_bits(), "east edge, row {i}");
        assert_eq!(sw[i].to_bits(), nw[(n - 1) * n + i].to_bits(), "north edge, column {i}");
    }
    // The same bytes as the library computes in process, in the query form too.
    let expected = sylva::produce::tile(&common::demo(), t, 0, Layer::Cem, Format::Bil32).unwrap().encoded.bytes;
    assert!(tile(t.row, t.col, "bil32").body == expected);
    let query = |more: &str| server.get(&format!("/tiles?T=cem&L={}&X={}&Y={}{more}", t.level, t.col, t.row));
    assert!(query("&F=bil32").body == expected && query("&FORMAT=application/bil32").body == expected);
    assert_eq!(query("&F=bil&FORMAT=image/png").status, 400, "two formats");
    let twice = query("&F=bil32&F=bil");
    assert!(twice.status == 400 && twice.text().contains("given twice"), "{}", twice.text());
    let relief = server.get(&format!("/tiles?T=relief&L={}&X={}&Y={}", t.level, t.col, t.row));
    assert!(relief.status == 200 && relief.header("content-type") == Some("image/png"), "{}", relief.text());
    let halo = server.get(&format!("/tiles/cem/{}/{}/{}_{}.bil32?halo=8", t.level, t.row, t.row, t.col));
    assert_eq!(halo.body.len(), (n + 16) * (n + 16) * 4);
    // Far from the region there is nothing: 404 with no body, and no cache
    // entry (regression: any client could add them without end).
    let absent = server.get("/tiles/cem/11/10/10_10.bil");
    assert_eq!((absent.status, absent.body.len()), (404, 0));
    let entries = crate::seed::walk(&dir.join("cache"));
    assert!(!entries.iter().any(|p| p.to_string_lossy().contains("10_10")), "{entries:?}");
}

#[test]
fn two_hundred_concurrent_requests_cause_one_computation() {
    let dir = TempDir::new("srv-flight");
    let server = Server::start(None, &dir.join("cache"));
    let t = demo_tile();
    let url = format!("{}/tiles/cem/{}/{}/{}_{}.png", server.base, t.level, t.row, t.row, t.col);
    let bodies: Vec<Vec<u8>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..200).map(|_| s.spawn(|| get(&url, &[]).body)).collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert!(bodies.iter().all(|b| !b.is_empty() && *b == bodies[0]));
    assert_eq!(server.metric("sylva_tile_computations_total"), 1.0);
}

#[test]
fn a_corrupt_cache_file_is_recomputed_not_served() {
    let dir = TempDir::new("srv-corrupt");
    let cache = dir.join("cache");
    let t = demo_tile();
    let path = format!("/tiles/dem/{}/{}/{}_{}.bil32", t.level, t.row, t.row, t.col);
    let first = {
        let server = Server::start(None, &cache);
        server.get(&path).body
    };
    let file = walk(&cache)
        .into_iter()
        .find(|p| p.to_string_lossy().ends_with(&format!("dem/{}/{}/{}_{}.bil32", t.level, t.row, t.row, t.col)))
        .expect("cached file");
    let mut bytes = std::fs::read(&file).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(&file, bytes).unwrap();
    let server = Server::start(None, &cache);
    let again = server.get(&path);
    assert!(again.body == first);
    assert_eq!(server.metric("sylva_tile_cache_total{result=\"corrupt\"}"), 1.0);
    assert_eq!(server.metric("sylva_tile_computations_total"), 1.0);
    // A second server on the same directory now reads the repaired file.
    let third = Server::start(None, &cache);
    assert!(third.get(&path).body == first);
    assert_eq!(third.metric("sylva_tile_computations_total"), 0.0);
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = entry.path();
        if p.is_dir() { out.extend(walk(&p)) } else { out.push(p) }
    }
    out
}

#[test]
fn bad_input_is_a_4xx_with_a_reason_never_a_5xx() {
    let dir = TempDir::new("srv-bad");
    let server = Server::start(None, &dir.join("cache"));
    let cases = [
        ("/wms", "MissingParameterValue"),
        ("/wms?REQUEST=GetMap", "MissingParameterValue"),
        (
            "/wms?REQUEST=GetMap&VERSION=1.3.0&LAYERS=trees&CRS=EPSG:4326&BBOX=0,0,1,1&WIDTH=10&HEIGHT=10&FORMAT=image/png",
            "LayerNotDefined",
        ),
        (
            "/wms?REQUEST=GetMap&VERSION=1.3.0&LAYERS=dem&CRS=EPSG:2193&BBOX=0,0,1,1&WIDTH=10&HEIGHT=10&FORMAT=image/png",
            "InvalidCRS",
        ),
        (
            "/wms?REQUEST=GetMap&VERSION=1.1.1&LAYERS=dem&SRS=EPSG:2193&BBOX=0,0,1,1&WIDTH=10&HEIGHT=10&FORMAT=image/png",
            "InvalidSRS",
        ),
        (
            "/wms?REQUEST=GetMap&VERSION=1.3.0&LAYERS=dem&CRS=EPSG:4326&BBOX=0,0,1,1&WIDTH=10&HEIGHT=10&FORMAT=image/gif",
            "InvalidFormat",
        ),
        (
            "/wms?REQUEST=GetMap&VERSION=1.3.0&LAYERS=dem&CRS=EPSG:4326&BBOX=1,0,0,1&WIDTH=10&HEIGHT=10&FORMAT=image/png",
            "InvalidParameterValue",
        ),
        (
            "/wms?REQUEST=GetMap&VERSION=1.3.0&LAYERS=dem&CRS=EPSG:4326&BBOX=0,0,1,1&WIDTH=100000&HEIGHT=10&FORMAT=image/png",
            "InvalidParameterValue",
        ),
        (
            "/wms?REQUEST=GetMap&VERSION=1.3.0&LAYERS=dem&CRS=EPSG:4326&BBOX=nan,0,1,1&WIDTH=10&HEIGHT=10&FORMAT=image/png",
            "InvalidParameterValue",
        ),
        ("/wms?REQUEST=DescribeLayer", "OperationNotSupported"),
        ("/wms?REQUEST=GetLegendGraphic", "MissingParameterValue"),
        ("/wms?REQUEST=GetLegendGraphic&LAYER=dem&WIDTH=0", "InvalidParameterValue"),
        ("/wms?REQUEST=GetLegendGraphic&LAYER=dem&FORMAT=application/bil32", "InvalidFormat"),
        ("/wms?REQUEST=GetFeatureInfo", "MissingParameterValue"),
        ("/tiles/cem/3/1/1_1.gif", ""),
        ("/tiles/trees/3/1/1_1.bil", ""),
        ("/tiles/cem/3/1/1_1.bil?halo=100000", ""),
        ("/tiles?T=cem&L=x&X=1&Y=1", ""),
        ("/xyz/cover/3/1/1.png", ""),
        ("/xyz/dem/3/1/1.jpg", "Terrarium .png"),
        ("/xyz/cover/tiles.json", "not a height"),
        ("/tiles/dem/-1/0/0_0.bil", "level must be a whole number"),
        ("/xyz/dem/12/-1/0.png", "x must be a whole number"),
        ("/tiles/relief/3/1/1_1.gif", ".png or .jpg"),
        ("/wmts/1.0.0/relief/default/Foo/12/0/0.png", "TILEMATRIXSET"),
        ("/wmts/1.0.0/dem/default/WorldCRS84Quad/3/8/0.png", "TileOutOfRange"),
        ("/wmts/1.0.0/dem/default/WorldCRS84Quad/3/0/16.png", "TileOutOfRange"),
        ("/wmts/1.0.0/dem/fancy/WorldCRS84Quad/3/0/0.png", "STYLE"),
        ("/wmts/1.0.0/dem/default/WorldCRS84Quad/3/0/0.tif", "FORMAT"),
        ("/cesium/cover/layer.json", "no terrain layer"),
        ("/wmts/1.0.0/dem/default/WorldCRS84Quad/3/0/%FF.png", "not UTF-8"),
        ("/wmts/1.0.0/relief/default/WorldCRS84Quad/3/0/0", "needs an extension"),
        ("/cesium/cem/0/0/0.png", "{y}.terrain"),
        ("/cesium/cem/0/0/x.terrain", "y must be a whole number"),
        ("/cesium/relief/0/0/0.terrain", "no terrain layer"),
        (
            "/wms?REQUEST=GetMap&VERSION=1.3.0&LAYERS=relief&CRS=EPSG:4326&BBOX=0,0,1,1&WIDTH=10&HEIGHT=10&FORMAT=application/bil16",
            "InvalidFormat",
        ),
        (
            "/wms?REQUEST=GetMap&VERSION=abc&LAYERS=dem&CRS=EPSG:4326&BBOX=0,0,1,1&WIDTH=10&HEIGHT=10&FORMAT=image/png",
            "1.1.1 and 1.3.0",
        ),
        (
            "/wms?REQUEST=GetMap&VERSION=1.3.0&LAYERS=dem&CRS=EPSG:4326&BBOX=0,0,1,1&WIDTH=10&HEIGHT=10&FORMAT=image/png&LAYERS=cem",
            "given twice",
        ),
        ("/tiles/cem/3/1/2_1.bil", "the file's row 2 is not the directory's, 1"),
        ("/tiles/cem/3/1/1.bil", "tile files are {row}_{col}.{ext}"),
        ("/tiles/cem/3/1/1_1", "tile files are {row}_{col}.{ext}"),
        // A tile of a matrix outside the layer's limits there.
        ("/wmts/1.0.0/dem/default/WorldCRS84Quad/3/0/0.png", "TileOutOfRange"),
    ];
    for (path, code) in cases {
        let r = server.get(path);
        assert!((400..500).contains(&r.status), "{path}: {} {}", r.status, r.text());
        assert!(r.text().contains(code), "{path}: {}", r.text());
    }
    let past_any_tile = [
        "/tiles/cem/99/1/1_1.bil",
        "/xyz/dem/3/99/1.png",
        "/xyz/dem/25/0/0.png",
        "/tiles/cem/3/99999999999999999999/1_1.bil",
        "/xyz/dem/3/1/99999999999999999999.png",
        "/cesium/cem/0/2/0.terrain",
        "/cesium/cem/1/0/0.terrain",
        "/cesium/cem/30/0/0.terrain",
        "/cesium/cem/99999999999/0/0.terrain",
        "/nowhere",
    ];
    for path in past_any_tile {
        assert_eq!(server.get(path).status, 404, "{path}");
    }
    let long = server.get(&format!("/wms?x={}", "a".repeat(10_000)));
    assert_eq!(long.status, 414);
    assert!(long.text().contains("ServiceExceptionReport"), "{}", long.text());
    let long = server.get(&format!("/wmts?x={}", "a".repeat(10_000)));
    assert!(long.status == 414 && long.text().contains("<ExceptionReport"), "{}", long.text());
    assert_eq!(server.get(&format!("/tiles?x={}", "a".repeat(10_000))).status, 414);
    assert_eq!(server.get("/health").status, 200, "still up");
}

#[test]
fn in_image_and_blank_exceptions_are_images() {
    let dir = TempDir::new("srv-inimage");
    let server = Server::start(None, &dir.join("cache"));
    let q = "/wms?REQUEST=GetMap&VERSION=1.1.1&LAYERS=trees&SRS=EPSG:4326&BBOX=0,0,1,1&WIDTH=200&HEIGHT=50&FORMAT=image/png";
    let inimage = server.get(&format!("{q}&EXCEPTIONS=application/vnd.ogc.se_inimage"));
    assert_eq!((inimage.status, inimage.header("content-type")), (200, Some("image/png")));
    let img = image::load_from_memory(&inimage.body).unwrap().into_rgba8();
    assert_eq!(img.dimensions(), (200, 50));
    assert!(img.pixels().any(|p| p.0[3] > 0));
    let blank = server.get(&format!("{q}&EXCEPTIONS=BLANK").replace("image/png", "application/bil16"));
    assert_eq!((blank.status, blank.body.len()), (200, 200 * 50 * 2));
    // Blank in the layer asked for: a DEM in PNG is 16-bit nodata (regression:
    // white relief, which reads as 9,330 m).
    let dem = server.get(&format!("{}&EXCEPTIONS=BLANK", q.replace("trees", "dem").replace("0,0,1,1", "1,0,0,1")));
    let img = image::load_from_memory(&dem.body).unwrap();
    assert!(matches!(&img, image::DynamicImage::ImageLuma16(_)), "{:?}", img.color());
    assert!(img.to_luma16().pixels().all(|p| p.0[0] == 0));
    // A key given twice still gets the image asked for (regression: a report).
    let twice = server.get(&format!("{}&EXCEPTIONS=INIMAGE&layers=cem", q.replace("trees", "relief")));
    assert_eq!((twice.status, twice.header("content-type")), (200, Some("image/png")), "{}", twice.text());
    let ambiguous = server.get(&format!("{q}&EXCEPTIONS=INIMAGE&exceptions=XML"));
    assert_eq!(ambiguous.status, 400, "an ambiguous style is the report");
}

#[test]
fn a_blank_geotiff_lies_where_the_map_was_asked_for() {
    let dir = TempDir::new("srv-blank-tiff");
    let server = Server::start(None, &dir.join("cache"));
    let q = "/wms?REQUEST=GetMap&VERSION=1.3.0&LAYERS=dem&CRS=EPSG:3857&BBOX=1118760,5836600,1130000,5844700&WIDTH=64&HEIGHT=48&FORMAT=image/tiff";
    let map = server.get(&format!("{q}&STYLES="));
    let blank = server.get(&format!("{q}&STYLES=bogus&EXCEPTIONS=BLANK"));
    assert_eq!((map.status, blank.status, blank.header("content-type")), (200, 200, Some("image/tiff")));
    // Tie point, pixel scale and GeoKeys: those of the map (regression:
    // a box of 0–1° in EPSG:4326, whatever was asked for).
    let georef = |tiff: &[u8]| {
        let mut decoder = tiff::decoder::Decoder::new(std::io::Cursor::new(tiff.to_vec())).unwrap();
        let mut tag = |code| decoder.get_tag_f64_vec(tiff::tags::Tag::Unknown(code)).unwrap();
        let (tie, scale) = (tag(33922), tag(33550));
        (tie, scale, decoder.get_tag_u16_vec(tiff::tags::Tag::Unknown(34735)).unwrap())
    };
    assert_eq!(georef(&blank.body), georef(&map.body));
    // A box that does not parse places no GeoTIFF: the report.
    let nowhere = server.get(&format!("{q}&STYLES=&EXCEPTIONS=BLANK").replace("BBOX=1118760", "BBOX=x"));
    assert_eq!(nowhere.status, 400, "{}", nowhere.text());
    assert!(nowhere.text().contains("ServiceExceptionReport"));
}

#[test]
fn tiles_carry_etags_cache_control_timing_and_gzip() {
    let dir = TempDir::new("srv-http");
    let server = Server::start(None, &dir.join("cache"));
    let t = demo_tile();
    let path = format!("/tiles/cem/{}/{}/{}_{}.png", t.level, t.row, t.row, t.col);
    let r = server.get(&path);
    let etag = r.header("etag").expect("etag").to_string();
    assert!(r.header("cache-control").unwrap().contains("max-age="));
    assert!(r.header("server-timing").unwrap().contains("elevation;dur="));
    assert_eq!(r.header("x-sylva-scale"), Some("0.15"));
    assert_eq!(server.get_with(&path, &[("If-None-Match", &etag)]).status, 304);
    // Weak comparison: a proxy may have weakened the tag, or strengthened it.
    let strong = etag.trim_start_matches("W/");
    assert_eq!(server.get_with(&path, &[("If-None-Match", &format!("\"x\", {strong}"))]).status, 304);
    assert_eq!(server.get_with(&path, &[("If-None-Match", "W/\"0000000000000000\"")]).status, 200);
    let bil = server.get_with(&path.replace(".png", ".bil"), &[("Accept-Encoding", "gzip")]);
    assert_eq!(bil.status, 200);
    assert_eq!(bil.body.len(), 513 * 513 * 2, "the client decompressed it");
    let raw = crate::http::get_raw(&format!("{}{}", server.base, path.replace(".png", ".bil")));
    assert_eq!(raw.header("content-encoding"), Some("gzip"));
    assert!(raw.body.len() < 513 * 513 * 2);
}

#[test]
fn cesium_terrain_covers_both_hemispheres_at_zoom_0_and_is_gzipped() {
    let dir = TempDir::new("srv-cesium");
    let server = Server::start(None, &dir.join("cache"));
    let doc: serde_json::Value = serde_json::from_slice(&server.get("/cesium/dem/layer.json").body).unwrap();
    assert_eq!((doc["format"].as_str(), doc["scheme"].as_str()), (Some("heightmap-1.0"), Some("tms")));
    assert_eq!(doc["tiles"][0], "{z}/{x}/{y}.terrain");
    assert_eq!(doc["available"][0][0], serde_json::json!({ "startX": 0, "startY": 0, "endX": 1, "endY": 0 }));
    // Cesium starts from both zoom-0 tiles: the western hemisphere holds no
    // data (the ellipsoid, 0 m: value 5000), the eastern the demo.
    let value = |b: &[u8], i: usize| u16::from_le_bytes([b[2 * i], b[2 * i + 1]]);
    for x in [0, 1] {
        let t = server.get(&format!("/cesium/dem/0/{x}/0.terrain"));
        assert_eq!((t.status, t.body.len()), (200, 65 * 65 * 2 + 2), "{}", t.text());
        assert_eq!(t.header("content-type"), Some("application/octet-stream"));
        assert!((0..65 * 65).all(|i| value(&t.body, i) == 5000), "zoom 0 is coarser than the demo");
        // Only the eastern one has a child: its north-west one (0–90° E,
        // 0–90° N), Cesium's bit 4.
        assert_eq!(t.body[65 * 65 * 2], if x == 1 { 4 } else { 0 });
    }
    // A tile over the demo holds its heights; BIL-like bodies are gzipped.
    let z = doc["maxzoom"].as_u64().unwrap() as u32;
    let (_, x, y) = common::demo_middle_tile(z);
    let path = format!("/cesium/dem/{z}/{x}/{y}.terrain");
    let heights: Vec<f64> =
        (0..65 * 65).map(|i| sylva::encode::heightmap::height(value(&server.get(&path).body, i))).collect();
    assert!(heights.iter().all(|h| (500.0..4000.0).contains(h)), "{:?}", &heights[..4]);
    let raw = crate::http::get_raw(&format!("{}{path}", server.base));
    assert!(
        raw.header("content-encoding") == Some("gzip") && raw.body.len() < 65 * 65 * 2,
        "{:?}",
        raw.header("content-encoding")
    );
}

#[test]
fn a_byte_range_of_a_tile_is_served() {
    let dir = TempDir::new("srv-range");
    let server = Server::start(None, &dir.join("cache"));
    let t = demo_tile();
    let path = format!("/tiles/dem/{}/{}/{}_{}.tif", t.level, t.row, t.row, t.col);
    let whole = server.get(&path);
    assert_eq!(whole.header("accept-ranges"), Some("bytes"));
    let len = whole.body.len();
    let range = |asked: &str, extra: &[(&str, &str)]| server.get_with(&path, &[&[("Range", asked)], extra].concat());
    let head = range("bytes=0-99", &[]);
    assert_eq!((head.status, head.header("content-range")), (206, Some(format!("bytes 0-99/{len}").as_str())));
    assert_eq!(head.body, whole.body[..100]);
    let tail = range("bytes=-10", &[]);
    assert_eq!((tail.status, &tail.body[..]), (206, &whole.body[len - 10..]));
    let past = range(&format!("bytes={len}-"), &[]);
    assert_eq!((past.status, past.header("content-range")), (416, Some(format!("bytes */{len}").as_str())));
    // Another unit, several ranges or an If-Range: the whole body.
    for (asked, extra) in [("items=0-5", None), ("bytes=0-9,20-29", None), ("bytes=0-9", Some(("If-Range", "W/\"x\"")))]
    {
        let reply = range(asked, extra.as_slice());
        assert_eq!((reply.status, reply.body.len()), (200, len), "{asked}");
    }
}

#[test]
fn xyz_tiles_are_terrarium_heights() {
    let dir = TempDir::new("srv-xyz");
    let server = Server::start(None, &dir.join("cache"));
    let (x, y) = sylva::grid::mercator::to_mercator(10.125, 46.375);
    let z = 12u32;
    let size = 2.0 * sylva::grid::mercator::HALF_WORLD_M / f64::from(1u32 << z);
    let (tx, ty) = (
        ((x + sylva::grid::mercator::HALF_WORLD_M) / size) as u64,
        ((sylva::grid::mercator::HALF_WORLD_M - y) / size) as u64,
    );
    let r = server.get(&format!("/xyz/dem/{z}/{tx}/{ty}.png"));
    assert_eq!(r.status, 200);
    let img = image::load_from_memory(&r.body).unwrap().into_rgb8();
    assert_eq!(img.dimensions(), (256, 256));
    let heights: Vec<f64> = img.pixels().map(|p| sylva::encode::terrarium::height(p.0)).collect();
    assert!(heights.iter().all(|h| (800.0..3600.0).contains(h)), "{:?}", &heights[..4]);
    assert_eq!(server.get(&format!("/xyz/relief/{z}/{tx}/{ty}.png")).status, 200);
    let jpeg = server.get(&format!("/xyz/relief/{z}/{tx}/{ty}.jpg"));
    assert_eq!((jpeg.status, jpeg.header("content-type")), (200, Some("image/jpeg")));
    assert_eq!(image::load_from_memory(&jpeg.body).unwrap().into_rgb8().dimensions(), (256, 256));
    // A MapLibre source finds the tiles through the layer's TileJSON.
    let doc: serde_json::Value = serde_json::from_slice(&server.get("/xyz/dem/tiles.json").body).unwrap();
    let template = doc["tiles"][0].as_str().unwrap();
    assert!(template.starts_with("http://") && template.ends_with("/xyz/dem/{z}/{x}/{y}.png"), "{template}");
    assert_eq!((doc["tilejson"].as_str(), doc["encoding"].as_str()), (Some("3.0.0"), Some("terrarium")));
    assert!((10..=sylva::server::MAX_XYZ_ZOOM as u64).contains(&doc["maxzoom"].as_u64().unwrap()), "{doc}");
    assert_eq!(doc["bounds"][0].as_f64(), Some(10.0));
}

#[test]
fn wmts_feature_info_gives_the_heights_the_tile_shows() {
    let dir = TempDir::new("srv-wmts-info");
    let server = Server::start(None, &dir.join("cache"));
    let (z, col, row) = (12, 2162, 1450);
    let tile = image::load_from_memory(&server.get(&format!("/xyz/cem/{z}/{col}/{row}.png")).body).unwrap().into_rgb8();
    let base = format!(
        "/wmts?SERVICE=WMTS&REQUEST=GetFeatureInfo&VERSION=1.0.0&LAYER=cem&STYLE=default&FORMAT=image/png\
         &TILEMATRIXSET=WebMercatorQuad&TILEMATRIX={z}&TILEROW={row}&TILECOL={col}&INFOFORMAT=application/json"
    );
    for (i, j) in [(0, 0), (255, 0), (17, 200), (255, 255)] {
        let reply = server.get(&format!("{base}&I={i}&J={j}"));
        assert_eq!(reply.header("content-type"), Some("application/json"), "{}", reply.text());
        let doc: serde_json::Value = serde_json::from_slice(&reply.body).unwrap();
        let value = doc["features"][0]["properties"]["value"].as_f64().unwrap();
        // Terrarium steps are 1/256 m.
        let shown = sylva::encode::terrarium::height(tile.get_pixel(i, j).0);
        assert!((value - shown).abs() <= 1.0 / 256.0, "pixel {i}, {j}: {value} m, the tile shows {shown} m");
    }
    // A pixel off the tile is the standard's code.
    let off = server.get(&format!("{base}&I=256&J=0"));
    assert!(off.status == 400 && off.text().contains("PointIJOutOfRange"), "{}", off.text());
}

#[test]
fn geographic_wmts_tiles_are_the_wms_map_of_their_box_and_cached() {
    let dir = TempDir::new("srv-wmts-crs84");
    let server = Server::start(None, &dir.join("cache"));
    let z = 12u32;
    let (size, col, from_south) = common::demo_middle_tile(z);
    let row = (1 << z) - 1 - from_south;
    let rest = server.get(&format!("/wmts/1.0.0/cem/default/WorldCRS84Quad/{z}/{row}/{col}.png"));
    assert_eq!((rest.status, rest.header("content-type")), (200, Some("image/png")), "{}", rest.text());
    let kvp = server.get(&format!(
        "/wmts?SERVICE=WMTS&REQUEST=GetTile&VERSION=1.0.0&LAYER=cem&STYLE=default&FORMAT=image/png\
         &TILEMATRIXSET=WorldCRS84Quad&TILEMATRIX={z}&TILEROW={row}&TILECOL={col}"
    ));
    assert_eq!(kvp.body, rest.body);
    assert_eq!(server.metric("sylva_tile_computations_total"), 1.0, "computed once");
    // The WMS map of the tile's box, 256 pixels square, in float32: the
    // same pixel centres, the same heights to a Terrarium step.
    let (west, north) = (-180.0 + col as f64 * size, 90.0 - row as f64 * size);
    let (east, south) = (west + size, north - size);
    let map = server.get(&format!(
        "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=cem&STYLES=&CRS=CRS:84\
         &BBOX={west},{south},{east},{north}&WIDTH=256&HEIGHT=256&FORMAT=application/bil32"
    ));
    assert_eq!((map.status, map.body.len()), (200, 256 * 256 * 4), "{}", map.text());
    let heights = map.body.chunks(4).map(|b| f64::from(f32::from_le_bytes(b.try_into().unwrap())));
    let tile = image::load_from_memory(&rest.body).unwrap().into_rgb8();
    assert_eq!(tile.dimensions(), (256, 256));
    for (i, (p, h)) in tile.pixels().zip(heights).enumerate() {
        let shown = sylva::encode::terrarium::height(p.0);
        assert!((shown - h).abs() <= 1.0 / 256.0, "pixel {i}: the tile {shown} m, the map {h} m");
    }
    // Kept in the tile cache beside the XYZ tiles.
    let version = std::fs::read_dir(dir.join("cache")).unwrap().map(|e| e.unwrap().path()).find(|p| p.is_dir());
    let stored = version.unwrap().join(format!("crs84/cem/{z}/{col}/{row}.png"));
    // (The file is the tile and the cache's 16-byte trailer.)
    let file = std::fs::read(&stored).unwrap_or_default();
    assert!(file.len() == rest.body.len() + 16 && file.starts_with(&rest.body), "{stored:?}: {} bytes", file.len());
    // A Web Mercator tile by the RESTful path is the XYZ tile.
    let via_wmts = server.get("/wmts/1.0.0/relief/default/WebMercatorQuad/12/1449/2161.jpg");
    assert_eq!((via_wmts.status, via_wmts.header("content-type")), (200, Some("image/jpeg")));
    assert_eq!(via_wmts.body, server.get("/xyz/relief/12/2161/1449.jpg").body);
}

#[test]
fn sigterm_stops_the_server_cleanly() {
    let dir = TempDir::new("srv-term");
    let server = Server::start(None, &dir.join("cache"));
    assert_eq!(server.get("/health").status, 200);
    let status = server.terminate();
    assert!(status.success(), "{status:?}");
}

#[test]
fn a_get_map_off_the_lattice_is_computed_once_for_its_retries() {
    // Regression: it was computed inside its request, anew for each retry,
    // so after a timeout every retry timed out the same way.
    let dir = TempDir::new("srv-image");
    let server = Server::start(None, &dir.join("cache"));
    let q = "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=dem&STYLES=&CRS=CRS:84&BBOX=10.01,46.31,10.04,46.33&WIDTH=37&HEIGHT=23&FORMAT=application/bil32";
    let first = server.get(q);
    assert_eq!((first.status, first.body.len()), (200, 37 * 23 * 4), "{}", first.text());
    assert_eq!(server.get(q).body, first.body);
    assert_eq!(server.metric("sylva_tile_computations_total"), 1.0);
    let other = server.get(&q.replace("WIDTH=37", "WIDTH=38"));
    assert_eq!((other.status, server.metric("sylva_tile_computations_total")), (200, 2.0));
}

#[test]
fn get_maps_on_the_tile_lattice_come_from_the_tile_cache() {
    let dir = TempDir::new("srv-stitch");
    let server = Server::start(None, &dir.join("cache"));
    let tiles = common::demo().tiles;
    let t = demo_tile();
    let (s, sector) = (tiles.spacing_deg(t.level), tiles.sector(t));
    let wms = |west: f64, south: f64, side: usize| {
        let (east, north) = (west + side as f64 * s, south + side as f64 * s);
        format!(
            "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=cem&STYLES=&CRS=CRS:84&BBOX={west},{south},{east},{north}&WIDTH={side}&HEIGHT={side}&FORMAT=application/bil32"
        )
    };
    // Pixel centres 600 × 600 samples from the tile's middle: parts of four tiles.
    let (west, south) = (sector.min_lon + 255.5 * s, sector.min_lat + 255.5 * s);
    let stitched = server.get(&wms(west, south, 600));
    assert_eq!(stitched.status, 200, "{}", stitched.text());
    assert_eq!(server.metric("sylva_tile_computations_total"), 4.0, "one computation per tile touched");
    let fetch = |dr: u64, dc: u64| {
        bil32(&server.get(&format!("/tiles/cem/{}/{}/{}_{}.bil32", t.level, t.row + dr, t.row + dr, t.col + dc)).body)
    };
    let quad = [[fetch(0, 0), fetch(0, 1)], [fetch(1, 0), fetch(1, 1)]];
    assert_eq!(server.metric("sylva_tile_computations_total"), 4.0, "the tiles were cached by the GetMap");
    let image = bil32(&stitched.body);
    for y in 0..600 {
        // Sample indices from tile t's south-west corner, northward and eastward.
        let gy = 256 + 599 - y;
        for x in 0..600 {
            let gx = 256 + x;
            let (dr, dc) = (gy / 512, gx / 512);
            let (i, j) = (gx - 512 * dc, 512 - (gy - 512 * dr));
            let expected = quad[dr][dc][j * 513 + i];
            assert_eq!(image[y * 600 + x].to_bits(), expected.to_bits(), "pixel ({x}, {y})");
        }
    }
    // GetFeatureInfo on the stitched map gives its values, to the bit.
    for (x, y) in [(0, 0), (599, 599), (257, 300), (256, 343)] {
        let info = wms(west, south, 600).replace("GetMap", "GetFeatureInfo")
            + &format!("&QUERY_LAYERS=cem&I={x}&J={y}&INFO_FORMAT=application/json");
        let doc: serde_json::Value = serde_json::from_str(&server.get(&info).text()).unwrap();
        let value = doc["features"][0]["properties"]["value"].as_f64();
        assert_eq!(value, Some(f64::from(image[y * 600 + x])), "({x}, {y}): {doc}");
    }
    // A GetMap whose pixel centres are exactly one tile's samples is that tile.
    let whole = server.get(&wms(sector.min_lon - 0.5 * s, sector.min_lat - 0.5 * s, 513));
    assert!(bil32(&whole.body) == quad[0][0]);
    assert_eq!(server.metric("sylva_tile_computations_total"), 4.0);
}

#[test]
fn get_feature_info_at_a_corner_of_four_tiles_is_the_map_to_the_bit() {
    // Regression: the pixel, computed alone at the map's own positions,
    // was 2 ulp from the tiles' value the map is stitched from.
    let dir = TempDir::new("srv-corner");
    let server = Server::start(None, &dir.join("cache"));
    let q = "/wms?SERVICE=WMS&VERSION=1.3.0&LAYERS=canopy&STYLES=&CRS=CRS:84&WIDTH=100&HEIGHT=80\
             &BBOX=10.105688095092773,46.38731575012207,10.109121322631836,46.39006233215332";
    let map = bil32(&server.get(&format!("{q}&REQUEST=GetMap&FORMAT=application/bil32")).body);
    let info = format!(
        "{q}&REQUEST=GetFeatureInfo&FORMAT=image/png&QUERY_LAYERS=canopy&I=50&J=40&INFO_FORMAT=application/json"
    );
    let doc: serde_json::Value = serde_json::from_str(&server.get(&info).text()).unwrap();
    assert_eq!(doc["features"][0]["properties"]["value"].as_f64(), Some(f64::from(map[40 * 100 + 50])), "{doc}");
}

#[test]
fn world_wind_dem_tiles_match_the_dem_at_their_samples() {
    let dir = TempDir::new("srv-rmnp");
    let server = Server::start(Some(&common::repo().join("config/examples/rmnp.toml")), &dir.join("cache"));
    // The DEM's pixels, decoded independently, and its georeferencing as gdalinfo prints it.
    let file = std::fs::File::open(common::data("rmnp/rmnp-dem.tif")).unwrap();
    let mut decoder = tiff::decoder::Decoder::new(std::io::BufReader::new(file)).unwrap();
    let (w, h) = decoder.dimensions().unwrap();
    let tiff::decoder::DecodingResult::U16(pixels) = decoder.read_image().unwrap() else {
        panic!("rmnp DEM is UInt16")
    };
    let (x0, y0, dx, dy) = (-105.912_500_000_000_01, 40.553_678_069_620_155, 0.00275, -0.00211);
    let dem = |px: usize, py: usize| f64::from(pixels[py * w as usize + px]);
    let tiles = common::region("examples/rmnp.toml").tiles;
    let t = tiles.tile_containing(-105.7, 40.35, 8);
    let reply = server.get(&format!("/tiles/dem/8/{}/{}_{}.bil32", t.row, t.row, t.col));
    assert_eq!(reply.status, 200);
    let values = bil32(&reply.body);
    let grid = tiles.tile_samples(t, 0);
    let mut checked = 0;
    for j in 0..513 {
        for i in 0..513 {
            let (lon, lat) = grid.lon_lat(i, j);
            // Bilinear between the four pixel centres around the sample.
            let (fx, fy) = ((lon - x0) / dx - 0.5, (lat - y0) / dy - 0.5);
            let (px, py) = (fx.floor(), fy.floor());
            if px < 0.0 || py < 0.0 || px + 1.0 >= f64::from(w) || py + 1.0 >= f64::from(h) {
                continue;
            }
            let (px, py, tx, ty) = (px as usize, py as usize, fx - fx.floor(), fy - fy.floor());
            let top = dem(px, py) * (1.0 - tx) + dem(px + 1, py) * tx;
            let bottom = dem(px, py + 1) * (1.0 - tx) + dem(px + 1, py + 1) * tx;
            let expected = top * (1.0 - ty) + bottom * ty;
            let got = f64::from(values[j * 513 + i]);
            assert!((got - expected).abs() < 1e-3, "sample ({i}, {j}) at {lon}, {lat}: {got} against {expected}");
            checked += 1;
        }
    }
    assert!(checked > 100_000, "only {checked} samples inside the DEM");
}

#[test]
fn an_overloaded_server_answers_503_with_retry_after_at_once() {
    let dir = TempDir::new("srv-busy");
    let config = dir.join("busy.toml");
    std::fs::write(&config, "[server]\nworkers = 1\nqueue = 0\n").unwrap();
    let server = Server::start(Some(&config), &dir.join("cache"));
    // Eight different uncached maps at once: one computes, the others find
    // no room, and are told so in a report whatever they asked (a refusal
    // costs nothing; a blank image may be as large as a map).
    let replies: Vec<_> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..8)
            .map(|i| {
                let url = format!(
                    "{}/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=cem&STYLES=&CRS=CRS:84&BBOX=10.0{i},46.3,10.2,46.45&WIDTH=900&HEIGHT=700&FORMAT=image/tiff&EXCEPTIONS=BLANK",
                    server.base
                );
                s.spawn(move || get(&url, &[]))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert!(
        replies.iter().all(|r| r.status == 200 || r.status == 503),
        "{:?}",
        replies.iter().map(|r| r.status).collect::<Vec<_>>()
    );
    let busy: Vec<_> = replies.iter().filter(|r| r.status == 503).collect();
    assert!(!busy.is_empty(), "no request was refused");
    for r in busy {
        assert_eq!(r.header("retry-after"), Some("1"));
        assert!(r.text().contains("ServiceExceptionReport") && r.text().contains("busy"), "{}", r.text());
    }
    assert!(replies.iter().any(|r| r.status == 200));
    assert_eq!(server.get("/health").status, 200);
}

#[test]
fn a_request_that_times_out_leaves_its_tile_computed_for_the_retry() {
    let dir = TempDir::new("srv-timeout");
    let config = dir.join("impatient.toml");
    // Far shorter than a tile's computation: every computing request gives up.
    std::fs::write(&config, "[server]\nrequest_timeout_s = 0.001\n").unwrap();
    let impatient = Server::start(Some(&config), &dir.join("cache"));
    let t = demo_tile();
    let path = format!("/tiles/cem/{}/{}/{}_{}.bil32?halo=8", t.level, t.row, t.row, t.col);
    assert_eq!(impatient.get(&path).status, 503, "the request gives up");
    let map = "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=cem&STYLES=&CRS=CRS:84&BBOX=10.01,46.31,10.24,46.44&WIDTH=300&HEIGHT=200&FORMAT=image/png";
    let wms = impatient.get(map);
    assert_eq!(wms.status, 503);
    assert!(wms.text().contains("<ServiceExceptionReport") && wms.text().contains("retry later"), "{}", wms.text());
    // Its retry waits for the same computation (regression: the first
    // request's timeout cancelled the wait, and the retry computed it anew).
    assert!([200, 503].contains(&impatient.get(map).status));
    // A patient server on the same cache waits for the abandoned computation.
    let patient = Server::start(None, &dir.join("cache"));
    assert_eq!(patient.get(&path).status, 200);
    assert_eq!(patient.metric("sylva_tile_computations_total"), 0.0, "the retry computed nothing");
    // The tile and the GetMap's image, each computed once, for their retries.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while impatient.metric("sylva_tile_computations_total") < 2.0 && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    std::thread::sleep(std::time::Duration::from_secs(2));
    assert_eq!(impatient.metric("sylva_tile_computations_total"), 2.0);
}

#[test]
fn a_failing_tile_cache_still_serves_and_one_unusable_at_start_is_refused() {
    let dir = TempDir::new("srv-broken-cache");
    let cache = dir.join("cache");
    let server = Server::start(None, &cache);
    // The cache directory turns into a file under the running server.
    std::fs::remove_dir_all(&cache).unwrap();
    std::fs::write(&cache, b"not a directory").unwrap();
    let t = demo_tile();
    let reply = server.get(&format!("/tiles/dem/{}/{}/{}_{}.bil32", t.level, t.row, t.row, t.col));
    assert_eq!((reply.status, reply.body.len()), (200, 513 * 513 * 4), "{}", reply.text());
    assert_eq!(server.metric("sylva_tile_cache_total{result=\"unavailable\"}"), 1.0);
    drop(server);
    // A server started on it says so and stops.
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_sylva"))
        .args(["serve", "--bind", "127.0.0.1:0", "--cache-dir"])
        .arg(&cache)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while child.try_wait().unwrap().is_none() {
        if std::time::Instant::now() > deadline {
            let _ = child.kill();
            panic!("sylva serve started on a file as its tile cache");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("must be a directory"), "{err}");
}

#[test]
fn wms_and_wmts_by_another_method_than_get_is_an_ogc_report() {
    let dir = TempDir::new("srv-post");
    let server = Server::start(None, &dir.join("cache"));
    let agent: ureq::Agent = ureq::Agent::config_builder().http_status_as_error(false).build().into();
    let rest = "wmts/1.0.0/dem/default/WorldCRS84Quad/3/0/0.png";
    for (service, report) in
        [("wms", "ServiceExceptionReport"), ("wmts", "<ExceptionReport"), (rest, "<ExceptionReport")]
    {
        let mut response = agent.post(&format!("{}/{service}", server.base)).send_empty().unwrap();
        assert_eq!(response.status().as_u16(), 405);
        assert_eq!(response.headers().get("allow").and_then(|v| v.to_str().ok()), Some("GET, HEAD"));
        let body = response.body_mut().read_to_string().unwrap();
        assert!(body.contains(report) && body.contains("OperationNotSupported"), "{body}");
    }
}
