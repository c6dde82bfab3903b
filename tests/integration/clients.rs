//! Real WMS clients against the real server: GDAL's WMS driver (`gdalinfo`,
//! `gdal_translate`, Debian `gdal-bin`) and OWSLib (Debian `python3-owslib`)
//! read the capabilities and fetch a `dem` map of rmnp whose values match
//! `sylva build` of the same grid; both read the WMTS too.

use crate::common::{self, TempDir};
use crate::http::Server;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The map fetched by every client: W, S, E, N and size in pixels.
const BOX: [f64; 4] = [-105.8, 40.25, -105.6, 40.45];
const SIDE: usize = 300;

fn rmnp_server(dir: &TempDir) -> Server {
    Server::start(Some(&common::repo().join("config/examples/rmnp.toml")), &dir.join("cache"))
}

/// `sylva build` of the map's pixel centres (a point-registered build of the
/// box shrunk by half a pixel).
fn reference(dir: &TempDir) -> Vec<f32> {
    let [w, s, e, n] = BOX;
    let half = 0.5 * (e - w) / SIDE as f64;
    let out = dir.join("reference.bil");
    let bbox = format!("{},{},{},{}", w + half, s + half, e - half, n - half);
    let config = common::repo().join("config/examples/rmnp.toml");
    let side = SIDE.to_string();
    let status = Command::new(env!("CARGO_BIN_EXE_sylva"))
        .args(["build", "--config"])
        .arg(&config)
        .args(["--layer", "dem", "--bbox", &bbox, "--width", &side, "--height", &side, "--format", "bil32", "-o"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let bytes = std::fs::read(&out).unwrap();
    bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

/// The float32 samples of a map's GeoTIFF, decoded with the `tiff` crate.
fn tiff_values(path: &Path) -> Vec<f32> {
    tiff_of_side(path, SIDE)
}

/// The float32 samples of a `side²` GeoTIFF.
fn tiff_of_side(path: &Path, side: usize) -> Vec<f32> {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut decoder = tiff::decoder::Decoder::new(std::io::BufReader::new(file)).unwrap();
    assert_eq!(decoder.dimensions().unwrap(), (side as u32, side as u32), "{}", path.display());
    match decoder.read_image().unwrap() {
        tiff::decoder::DecodingResult::F32(v) => v,
        _ => panic!("{}: not float32", path.display()),
    }
}

fn assert_matches(client: &str, got: &[f32], reference: &[f32]) {
    assert_eq!(got.len(), reference.len(), "{client}");
    let worst = got.iter().zip(reference).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 0.01, "{client}: differs from sylva build by up to {worst} m");
    assert!(reference.iter().all(|v| (2000.0..4500.0).contains(v)), "the box lies inside the DEM");
}

fn run(cmd: &mut Command, what: &str) -> String {
    // GDAL's WMS and WMTS drivers would cache tiles in the working directory.
    let out = cmd
        .env("GDAL_ENABLE_WMS_CACHE", "NO")
        .output()
        .unwrap_or_else(|e| panic!("{what} ({e}): install it with `bash scripts/setup.sh`"));
    assert!(
        out.status.success(),
        "{what} failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A GDAL WMS service description of the map for `version`.
fn gdal_description(base: &str, version: &str) -> String {
    let [w, s, e, n] = BOX;
    let crs = match version {
        "1.1.1" => "<SRS>EPSG:4326</SRS>".to_string(),
        // GDAL 3.6 does not swap EPSG:4326 axes by itself; say so.
        _ => "<CRS>EPSG:4326</CRS><BBoxOrder>yxYX</BBoxOrder>".to_string(),
    };
    format!(
        "<GDAL_WMS><Service name=\"WMS\"><Version>{version}</Version><ServerUrl>{base}/wms?</ServerUrl>{crs}\
         <ImageFormat>image/tiff</ImageFormat><Layers>dem</Layers></Service>\
         <DataWindow><UpperLeftX>{w}</UpperLeftX><UpperLeftY>{n}</UpperLeftY><LowerRightX>{e}</LowerRightX><LowerRightY>{s}</LowerRightY>\
         <SizeX>{SIDE}</SizeX><SizeY>{SIDE}</SizeY></DataWindow>\
         <BandsCount>1</BandsCount><DataType>Float32</DataType><BlockSizeX>128</BlockSizeX><BlockSizeY>128</BlockSizeY></GDAL_WMS>"
    )
}

#[test]
fn gdal_reads_the_capabilities_and_a_dem_map_that_matches_build() {
    let dir = TempDir::new("client-gdal");
    let server = rmnp_server(&dir);
    let info = run(Command::new("gdalinfo").arg(format!("WMS:{}/wms", server.base)), "gdalinfo");
    for layer in ["dem", "cover", "canopy", "cem", "surface", "colour", "relief"] {
        assert!(info.contains(&format!("LAYERS={layer}&")), "gdalinfo lists {layer}:\n{info}");
    }
    assert!(info.contains("SUBDATASET_1_DESC=Ground elevation (m)"), "{info}");
    let reference = reference(&dir);
    for version in ["1.1.1", "1.3.0"] {
        let xml = dir.join(&format!("wms-{version}.xml"));
        std::fs::write(&xml, gdal_description(&server.base, version)).unwrap();
        let out = dir.join(&format!("gdal-{version}.tif"));
        run(Command::new("gdal_translate").arg("-q").arg(&xml).arg(&out), "gdal_translate");
        assert_matches(&format!("GDAL WMS {version}"), &tiff_values(&out), &reference);
        // The geotransform GDAL gives the map is the box's.
        let info = run(Command::new("gdalinfo").arg(&out), "gdalinfo");
        assert!(info.contains("Origin = (-105.7999999") || info.contains("Origin = (-105.800000"), "{info}");
    }
}

/// A Python with OWSLib: Debian's (`python3-owslib`), else the one on PATH.
fn python_with_owslib() -> PathBuf {
    for python in ["/usr/bin/python3", "python3"] {
        let ok = Command::new(python).args(["-c", "import owslib"]).output().is_ok_and(|o| o.status.success());
        if ok {
            return PathBuf::from(python);
        }
    }
    panic!("no Python with OWSLib: install it with `bash scripts/setup.sh` (Debian python3-owslib)")
}

#[test]
fn owslib_reads_the_capabilities_and_a_dem_map_that_matches_build() {
    let dir = TempDir::new("client-owslib");
    let server = rmnp_server(&dir);
    let reference = reference(&dir);
    let [w, s, e, n] = BOX;
    for version in ["1.1.1", "1.3.0"] {
        let out = dir.join(&format!("owslib-{version}.tif"));
        // OWSLib swaps 1.3.0's EPSG:4326 box to lat,lon itself.
        let script = format!(
            "import sys\nfrom owslib.wms import WebMapService\n\
             wms = WebMapService('{base}/wms', version='{version}')\n\
             assert list(wms.contents) == ['dem', 'cover', 'canopy', 'cem', 'surface', 'colour', 'relief'], list(wms.contents)\n\
             assert wms['dem'].title == 'Ground elevation (m)'\n\
             assert 'GetLegendGraphic' in [op.name for op in wms.operations]\n\
             from urllib.request import urlopen\n\
             legend = urlopen(wms['relief'].styles['default']['legend']).read()\n\
             assert legend[:8] == b'\\x89PNG\\r\\n\\x1a\\n', legend[:200]\n\
             img = wms.getmap(layers=['dem'], srs='EPSG:4326', bbox=({w}, {s}, {e}, {n}), size=({SIDE}, {SIDE}), format='image/tiff')\n\
             open(sys.argv[1], 'wb').write(img.read())\n",
            base = server.base
        );
        run(Command::new(python_with_owslib()).args(["-c", &script]).arg(&out), "OWSLib");
        assert_matches(&format!("OWSLib {version}"), &tiff_values(&out), &reference);
    }
}

#[test]
fn the_shipped_gdal_description_reads_the_demo_heights() {
    let dir = TempDir::new("client-gdal-doc");
    let server = Server::start(None, &dir.join("cache"));
    let shipped = std::fs::read_to_string(common::repo().join("docs/gdal-dem.xml")).unwrap();
    assert!(shipped.starts_with("<GDAL_WMS>"), "GDAL reads nothing before the element");
    let xml = dir.join("gdal-dem.xml");
    std::fs::write(&xml, shipped.replace("http://127.0.0.1:8080", &server.base)).unwrap();
    let out = dir.join("dem.tif");
    run(Command::new("gdal_translate").arg("-q").arg(&xml).arg(&out), "gdal_translate");
    let mut decoder = tiff::decoder::Decoder::new(std::io::BufReader::new(std::fs::File::open(&out).unwrap())).unwrap();
    assert_eq!(decoder.dimensions().unwrap(), (1024, 614));
    let tiff::decoder::DecodingResult::F32(heights) = decoder.read_image().unwrap() else { panic!("not float32") };
    // The demo valley's floor and summits, no nodata.
    assert!(
        heights.iter().all(|h| (500.0..4000.0).contains(h)),
        "{:?}",
        heights.iter().fold((f32::MAX, f32::MIN), |(a, b), &h| (a.min(h), b.max(h)))
    );
}

/// GDAL's plain `WMS:` URL of a layer over the demo (no service description).
fn plain_url(server: &Server, layer: &str) -> String {
    let query =
        format!("SERVICE=WMS&VERSION=1.1.1&REQUEST=GetMap&LAYERS={layer}&SRS=EPSG:4326&BBOX=10.0,46.3,10.25,46.45");
    format!("WMS:{}/wms?{query}", server.base)
}

/// GDAL's plain `WMS:` URL of the demo's relief.
fn plain_relief_url(server: &Server) -> String {
    plain_url(server, "relief")
}

#[test]
fn gdal_reads_every_layer_from_a_plain_wms_url_in_its_default_jpeg() {
    // Regression: a data layer in JPEG was refused, so each of GDAL's
    // subdatasets but the pictures failed to open.
    let dir = TempDir::new("client-gdal-jpeg");
    let server = Server::start(None, &dir.join("cache"));
    for layer in ["relief", "dem", "cem", "canopy", "surface"] {
        let out = dir.join(&format!("{layer}.png"));
        let url = plain_url(&server, layer);
        run(
            Command::new("gdal_translate").args(["-q", "-outsize", "256", "154"]).arg(&url).arg(&out),
            "gdal_translate",
        );
        let picture = image::open(&out).unwrap();
        assert_eq!(picture.color(), image::ColorType::Rgb8, "{layer}: GDAL reads three 8-bit bands");
        let grey: Vec<f64> = picture.into_luma8().pixels().map(|p| f64::from(p.0[0])).collect();
        let mean = grey.iter().sum::<f64>() / grey.len() as f64;
        let sd = (grey.iter().map(|g| (g - mean).powi(2)).sum::<f64>() / grey.len() as f64).sqrt();
        assert!((40.0..220.0).contains(&mean) && sd > 10.0, "{layer}: a map, not a blank: mean {mean:.0}, sd {sd:.0}");
    }
}

#[test]
fn gdal_locationinfo_reads_the_heights_under_a_point() {
    let dir = TempDir::new("client-gdal-info");
    let server = Server::start(None, &dir.join("cache"));
    let url = plain_relief_url(&server);
    // GDAL asks GetFeatureInfo for GML and prints it per band.
    let report = run(Command::new("gdallocationinfo").args(["-wgs84", &url, "10.125", "46.375"]), "gdallocationinfo");
    let dem = report
        .split("<sylva:dem")
        .nth(1)
        .and_then(|f| f.split("<sylva:value>").nth(1))
        .and_then(|v| v.split('<').next())
        .and_then(|v| v.parse::<f64>().ok())
        .unwrap_or_else(|| panic!("no dem value in:\n{report}"));
    assert!((500.0..4000.0).contains(&dem), "{dem}");
    assert!(report.contains("<sylva:class>"), "the surface class is named:\n{report}");
}

#[test]
fn gdal_opens_a_served_geotiff_by_its_url() {
    // GDAL's `/vsicurl/` (QGIS's raster layer from a URL) reads byte
    // ranges (regression: "Range downloading not supported by this server").
    let dir = TempDir::new("client-gdal-vsicurl");
    let server = Server::start(None, &dir.join("cache"));
    let b = common::demo().bounds;
    let t = common::demo().tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 11);
    let path = format!("/tiles/dem/{}/{}/{}_{}.tif", t.level, t.row, t.row, t.col);
    let direct = dir.join("direct.tif");
    std::fs::write(&direct, server.get(&path).body).unwrap();
    let out = dir.join("vsicurl.tif");
    let url = format!("/vsicurl/{}{path}", server.base);
    run(Command::new("gdal_translate").args(["-q", &url]).arg(&out), "gdal_translate");
    assert_eq!(tiff_of_side(&out, 513), tiff_of_side(&direct, 513));
}

/// The deepest zoom of the WMTS layers' TileJSONs.
fn deepest_zoom(server: &Server) -> u32 {
    let zoom = |layer: &str| {
        let doc: serde_json::Value =
            serde_json::from_slice(&server.get(&format!("/xyz/{layer}/tiles.json")).body).unwrap();
        doc["maxzoom"].as_u64().unwrap() as u32
    };
    ["dem", "canopy", "cem", "colour", "relief"].map(zoom).into_iter().max().unwrap()
}

/// GDAL's `WMTS:` name of a layer of the demo in the Web Mercator set.
fn wmts_layer(server: &Server, layer: &str) -> String {
    wmts_layer_in(server, layer, "WebMercatorQuad")
}

/// GDAL's `WMTS:` name of a layer of the demo in a tile matrix set.
fn wmts_layer_in(server: &Server, layer: &str, set: &str) -> String {
    format!("WMTS:{}/wmts?SERVICE=WMTS&REQUEST=GetCapabilities,layer={layer},tilematrixset={set}", server.base)
}

#[test]
fn gdal_reads_the_wmts_layers_and_their_heights() {
    let dir = TempDir::new("client-gdal-wmts");
    let server = Server::start(None, &dir.join("cache"));
    let info = run(Command::new("gdalinfo").arg(format!("WMTS:{}/wmts", server.base)), "gdalinfo");
    for layer in ["dem", "canopy", "cem", "colour", "relief"] {
        for set in ["WebMercatorQuad", "WorldCRS84Quad"] {
            let name = format!(",layer={layer},tilematrixset={set}\n");
            assert!(info.contains(&name), "gdalinfo lists {layer} in {set}:\n{info}");
        }
    }
    // The layer's box is the region's, in Web Mercator, to a pixel of the
    // deepest zoom any layer's sources are as fine as (the relief's).
    let info = run(Command::new("gdalinfo").arg(wmts_layer(&server, "cem")), "gdalinfo");
    let deepest = deepest_zoom(&server);
    let pixel_m = 2.0 * sylva::grid::mercator::HALF_WORLD_M / (256.0 * 2f64.powi(deepest as i32));
    let b = common::demo().bounds;
    let corners = [(corner(&info, "Upper Left"), (b.west, b.north)), (corner(&info, "Lower Right"), (b.east, b.south))];
    for ((x, y), (lon, lat)) in corners {
        let (mx, my) = sylva::grid::mercator::to_mercator(lon, lat);
        assert!((x - mx).abs() <= pixel_m && (y - my).abs() <= pixel_m, "({x}, {y}) vs ({mx}, {my}):\n{info}");
    }
    assert_demo_heights(&dir.join("cem.png"), &wmts_layer(&server, "cem"));
    // GDAL's identify asks GetFeatureInfo (GML) of the tile under the point.
    let args = ["-b", "1", "-wgs84", &wmts_layer(&server, "dem"), "10.125", "46.375"];
    let report = run(Command::new("gdallocationinfo").args(args), "gdallocationinfo");
    let dem = report
        .split("<sylva:value>")
        .nth(1)
        .and_then(|v| v.split('<').next())
        .and_then(|v| v.parse::<f64>().ok())
        .unwrap_or_else(|| panic!("no dem value in:\n{report}"));
    assert!((500.0..4000.0).contains(&dem), "{dem}");
}

/// The (x, y) gdalinfo gives a corner (`Upper Left`, …) of its raster.
fn corner(info: &str, name: &str) -> (f64, f64) {
    let text = info.split(name).nth(1).and_then(|t| t.split(')').next()).unwrap_or_else(|| panic!("{info}"));
    let xy: Vec<f64> = text.trim_start_matches([' ', '(']).split(',').map(|v| v.trim().parse().unwrap()).collect();
    (xy[0], xy[1])
}

/// Reads GDAL's dataset `name` (a layer of CEM heights over the demo) to
/// `out`, 256 pixels wide, and checks the Terrarium heights it holds.
fn assert_demo_heights(out: &Path, name: &str) {
    // Nearest neighbour: averaged codes are no heights.
    let args = ["-q", "-r", "nearest", "-outsize", "256", "0"];
    run(Command::new("gdal_translate").args(args).arg(name).arg(out), "gdal_translate");
    let rgb = image::open(out).unwrap().into_rgb8();
    let heights: Vec<f64> = rgb.pixels().map(|p| sylva::encode::terrarium::height(p.0)).collect();
    let (low, high) = heights.iter().fold((f64::MAX, f64::MIN), |(a, b), &h| (a.min(h), b.max(h)));
    assert!(low > 500.0 && high < 4000.0 && high - low > 1000.0, "{name}: {low} to {high} m");
}

#[test]
fn gdal_reads_the_geographic_wmts_to_the_region_and_a_pixel() {
    let dir = TempDir::new("client-gdal-wmts-crs84");
    let server = Server::start(None, &dir.join("cache"));
    let name = wmts_layer_in(&server, "cem", "WorldCRS84Quad");
    let info = run(Command::new("gdalinfo").arg(&name), "gdalinfo");
    assert!(info.contains("ID[\"OGC\",\"CRS84\"]"), "{info}");
    // Square pixels of a geographic matrix: 180° / 256 / 2^z.
    let size =
        info.split("Pixel Size = (").nth(1).and_then(|t| t.split(')').next()).unwrap_or_else(|| panic!("{info}"));
    let size: Vec<f64> = size.split(',').map(|v| v.trim().parse().unwrap()).collect();
    let zoom = (180.0 / 256.0 / size[0]).log2();
    assert!(size[1] == -size[0] && (zoom - zoom.round()).abs() < 1e-9 && zoom > 10.0, "{info}");
    // The box is the region's to a pixel.
    let b = common::demo().bounds;
    for ((x, y), (lon, lat)) in
        [(corner(&info, "Upper Left"), (b.west, b.north)), (corner(&info, "Lower Right"), (b.east, b.south))]
    {
        assert!((x - lon).abs() <= size[0] && (y - lat).abs() <= size[0], "({x}, {y}) vs ({lon}, {lat}):\n{info}");
    }
    assert_demo_heights(&dir.join("cem.png"), &name);
    // GDAL's identify: the GetFeatureInfo of the pixel under the point.
    let args = ["-b", "1", "-wgs84", &name, "10.125", "46.375"];
    let report = run(Command::new("gdallocationinfo").args(args), "gdallocationinfo");
    let at = report
        .split("<gml:coordinates>")
        .nth(1)
        .and_then(|t| t.split('<').next())
        .unwrap_or_else(|| panic!("{report}"));
    let at: Vec<f64> = at.split(',').map(|v| v.parse().unwrap()).collect();
    assert!((at[0] - 10.125).abs() <= size[0] && (at[1] - 46.375).abs() <= size[0], "{report}");
}

#[test]
fn owslib_reads_both_wmts_matrix_sets_and_their_tiles() {
    let dir = TempDir::new("client-owslib-wmts");
    let server = Server::start(None, &dir.join("cache"));
    let out = dir.join("tile.jpg");
    let script = format!(
        "import sys\nfrom owslib.wmts import WebMapTileService\n\
         wmts = WebMapTileService('{base}/wmts')\n\
         assert list(wmts.contents) == ['dem', 'canopy', 'cem', 'colour', 'relief'], list(wmts.contents)\n\
         assert wmts['relief'].formats == ['image/png', 'image/jpeg'], wmts['relief'].formats\n\
         assert sorted(wmts.tilematrixsets) == ['WebMercatorQuad', 'WorldCRS84Quad'], list(wmts.tilematrixsets)\n\
         assert len(wmts.tilematrixsets['WebMercatorQuad'].tilematrix) == {matrices}\n\
         tile = wmts.gettile(layer='relief', tilematrixset='WebMercatorQuad', tilematrix='12', row=1449, column=2161, format='image/jpeg')\n\
         open(sys.argv[1], 'wb').write(tile.read())\n\
         tile = wmts.gettile(layer='relief', tilematrixset='WorldCRS84Quad', tilematrix='12', row=992, column=4326, format='image/png')\n\
         open(sys.argv[2], 'wb').write(tile.read())\n",
        base = server.base,
        matrices = deepest_zoom(&server) + 1
    );
    let geographic = dir.join("geographic.png");
    run(Command::new(python_with_owslib()).args(["-c", &script]).arg(&out).arg(&geographic), "OWSLib");
    let xyz = server.get("/xyz/relief/12/2161/1449.jpg");
    assert_eq!(xyz.status, 200);
    assert_eq!(std::fs::read(&out).unwrap(), xyz.body);
    let rest = server.get("/wmts/1.0.0/relief/default/WorldCRS84Quad/12/992/4326.png");
    assert_eq!((rest.status, rest.header("content-type")), (200, Some("image/png")));
    assert_eq!(std::fs::read(&geographic).unwrap(), rest.body);
}

/// The directory with CesiumJS's engine and the script that reads a terrain
/// tile with it.
fn cesium_dir() -> PathBuf {
    let dir = common::repo().join("tests/cesium");
    assert!(
        dir.join("node_modules/@cesium/engine").is_dir(),
        "no CesiumJS in {dir:?}: install it with `bash scripts/setup.sh`"
    );
    dir
}

/// What CesiumJS reads of a terrain tile (`tests/cesium/terrain.mjs`'s
/// arguments: the layer's URL, zoom, x, y from the south).
fn cesium_reads(args: &[String]) -> serde_json::Value {
    let out = run(Command::new("node").current_dir(cesium_dir()).arg("terrain.mjs").args(args), "node (CesiumJS)");
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out:.300}"))
}

#[test]
fn cesium_draws_water_where_the_surface_is_water() {
    let dir = TempDir::new("client-cesium-water");
    let server = Server::start(None, &dir.join("cache"));
    let layer_json: serde_json::Value = serde_json::from_slice(&server.get("/cesium/dem/layer.json").body).unwrap();
    // A tile over the demo's lake and its north-eastern shore.
    let z = layer_json["maxzoom"].as_u64().unwrap() as u32 - 2;
    let size = 180.0 / f64::from(1u32 << z);
    let (x, y) = (((10.10 + 180.0) / size) as u64, ((46.36 + 90.0) / size) as u64);
    let args = [format!("{}/cesium/dem", server.base), z.to_string(), x.to_string(), y.to_string()];
    let mask: Vec<u64> = cesium_reads(&args)["water"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
    // The surface classes at the centres of 256² pixels over the tile.
    let (west, south) = (-180.0 + x as f64 * size, -90.0 + y as f64 * size);
    let (east, north) = (west + size, south + size);
    let map = server.get(&format!(
        "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=surface&STYLES=&CRS=CRS:84\
         &BBOX={west},{south},{east},{north}&WIDTH=256&HEIGHT=256&FORMAT=application/bil16"
    ));
    assert_eq!((map.status, map.body.len()), (200, 256 * 256 * 2), "{}", map.text());
    let water = sylva::cem::surface::SurfaceType::Water as i16;
    let expected: Vec<u64> =
        map.body.chunks(2).map(|b| if i16::from_le_bytes([b[0], b[1]]) == water { 255 } else { 0 }).collect();
    let lake = expected.iter().filter(|&&m| m == 255).count();
    assert!(lake > 1000 && lake < 256 * 256 - 1000, "the tile holds water and land: {lake} water pixels");
    assert_eq!(mask.len(), expected.len());
    assert!(mask == expected, "{} texels differ", mask.iter().zip(&expected).filter(|(a, b)| a != b).count());
}

#[test]
fn cesium_reads_the_terrain_and_its_heights_are_the_wms_map_at_its_samples() {
    let dir = TempDir::new("client-cesium");
    let server = Server::start(None, &dir.join("cache"));
    let layer_json: serde_json::Value = serde_json::from_slice(&server.get("/cesium/cem/layer.json").body).unwrap();
    let z = layer_json["maxzoom"].as_u64().unwrap() as u32;
    let (size, x, y) = common::demo_middle_tile(z);
    let args = [format!("{}/cesium/cem", server.base), z.to_string(), x.to_string(), y.to_string()];
    let doc = cesium_reads(&args);
    assert_eq!(doc["available"], true);
    assert_eq!(doc["children"], serde_json::json!([false, false, false, false]), "the deepest zoom has no children");
    // The WMS map whose pixel centres are the tile's samples: its box is the
    // tile's grown by half a sample spacing.
    let d = size / 64.0;
    let (west, south) = (-180.0 + x as f64 * size - d / 2.0, -90.0 + y as f64 * size - d / 2.0);
    let (east, north) = (west + size + d, south + size + d);
    let map = server.get(&format!(
        "/wms?SERVICE=WMS&VERSION=1.3.0&REQUEST=GetMap&LAYERS=cem&STYLES=&CRS=CRS:84\
         &BBOX={west},{south},{east},{north}&WIDTH=65&HEIGHT=65&FORMAT=application/bil32"
    ));
    assert_eq!((map.status, map.body.len()), (200, 65 * 65 * 4), "{}", map.text());
    let expected = map.body.chunks(4).map(|b| f64::from(f32::from_le_bytes(b.try_into().unwrap())));
    let heights = doc["heights"].as_array().unwrap();
    assert_eq!(heights.len(), 65 * 65);
    // Half a 0.2 m step, and rounding in Cesium's interpolation.
    for (i, (got, want)) in heights.iter().zip(expected).enumerate() {
        let got = got.as_f64().unwrap();
        assert!((got - want).abs() <= 0.1 + 1e-3, "sample {i}: Cesium {got} m, the map {want} m");
    }
    // A tile one zoom up has the tile as a child, where Cesium looks for it.
    let parent = [args[0].clone(), (z - 1).to_string(), (x / 2).to_string(), (y / 2).to_string()];
    let doc = cesium_reads(&parent);
    let child = (x % 2 + 2 * (y % 2)) as usize;
    assert_eq!(doc["children"][child], true, "{:?}", doc["children"]);
}
