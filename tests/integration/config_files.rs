//! Every configuration file shipped in `config/` parses, validates and opens
//! its sources; bad configurations are refused with the file and the problem.

use crate::common::{self, TempDir};
use std::path::Path;

fn toml_files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).expect("config dir").flatten() {
        let path = entry.path();
        if path.is_dir() {
            // Camera paths are not regions (tested below).
            if path.file_name().is_some_and(|n| n != "paths") {
                out.extend(toml_files(&path));
            }
        } else if path.extension().is_some_and(|e| e == "toml") {
            out.push(path);
        }
    }
    out
}

#[test]
fn every_shipped_config_builds_its_region() {
    let files = toml_files(&common::repo().join("config"));
    assert!(files.len() >= 5, "{files:?}");
    for file in files {
        let region = sylva::config::load(Some(&file)).unwrap_or_else(|e| panic!("{e}"));
        assert!(!region.describe().is_empty());
    }
}

#[test]
fn every_shipped_camera_path_parses() {
    let dir = common::repo().join("config/paths");
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).expect("config/paths").flatten() {
        let path = sylva::client::path::CameraPath::load(&entry.path()).unwrap_or_else(|e| panic!("{e}"));
        assert!(path.key.len() >= 2, "{}: a path moves", entry.path().display());
        count += 1;
    }
    assert!(count >= 6, "demo and rmnp paths: valley, horizon, dive");
}

#[test]
fn the_default_file_is_the_built_in_default() {
    let from_file = sylva::config::load(Some(&common::repo().join("config/default.toml"))).expect("default.toml");
    let built_in = common::demo();
    assert_eq!(from_file.describe(), built_in.describe());
}

/// The colour keys `default.toml` shows, commented out, are the ones the
/// demo uses when none are given.
#[test]
fn the_default_files_commented_keys_are_the_demo_palette() {
    let text = std::fs::read_to_string(common::repo().join("config/default.toml")).expect("default.toml");
    let lines: Vec<&str> = text.lines().skip_while(|l| !l.starts_with("# keys = [")).collect();
    let end = lines.iter().position(|l| *l == "# ]").expect("the keys' closing bracket");
    let block: String = lines[..=end].iter().map(|l| format!("{}\n", &l[2..])).collect();
    #[derive(serde::Deserialize)]
    struct Keys {
        keys: Vec<sylva::cem::colorkey::ColorKey>,
    }
    let shown: Keys = toml::from_str(&block).expect("the keys parse once uncommented");
    assert_eq!(shown.keys, sylva::config::demo_keys());
}

#[test]
fn a_cache_bound_is_a_size_in_any_unit_or_bytes() {
    let dir = TempDir::new("cache-bound");
    for (given, bytes) in [("\"20GiB\"", 20u64 << 30), ("\"500 MB\"", 500_000_000), ("1000000", 1_000_000)] {
        let path = dir.join("bound.toml");
        std::fs::write(&path, format!("[tile_cache]\nmax_size = {given}\n")).unwrap();
        let (config, _) = sylva::config::load_with_config(Some(&path)).unwrap();
        assert_eq!(config.tile_cache.max_size, Some(bytes), "{given}");
    }
}

#[test]
fn bad_configs_name_the_file_and_the_problem() {
    let dir = TempDir::new("bad-config");
    let cases = [
        ("missing.toml", "[dem]\npath = \"nowhere.tif\"\n", "missing.toml: [dem] path: "),
        ("typo.toml", "[dem]\npaht = \"x.tif\"\n", "unknown field `paht`"),
        ("delta.toml", "[grid]\nlevel0_delta_deg = 7.0\n", "must divide 180"),
        ("close.toml", "[landcover]\nkind = \"map\"\nclose = \"DXE\"\n", "sequence of D and E"),
        ("radius.toml", "[landcover]\nkind = \"map\"\nclose_radius_px = 100000\n", "at most 32 pixels"),
        ("samples.toml", "[grid]\ntile_samples = 65536\n", "2 to 4097 samples"),
        ("gaps.toml", "[canopy]\ngap_fraction = 1.5\n", "[canopy] gap_fraction = 1.5: must be 0 to 1"),
        ("tall.toml", "[canopy]\nheight_m = inf\n", "[canopy] height_m = inf"),
        ("offset.toml", "[encoding]\npng16_offset_m = inf\n", "png16_offset_m must be a finite number"),
        (
            "timeout.toml",
            "[server]\nrequest_timeout_s = 1e20\n",
            "[server] request_timeout_s = 100000000000000000000: must be",
        ),
        ("no_timeout.toml", "[server]\nrequest_timeout_s = 0\n", "request_timeout_s = 0: must be above 0"),
        ("workers.toml", "[server]\nworkers = 100000\n", "[server] workers = 100000: must be at most 1024"),
        ("queue.toml", "[server]\nqueue = 9223372036854775807\n", "queue = 9223372036854775807: must be at most"),
        ("bind.toml", "[server]\nbind = \"nonsense\"\n", "[server] bind = \"nonsense\": must be HOST:PORT"),
        ("size.toml", "[server]\nmax_size = 0\n", "max_size = 0: must be 1 to 8193"),
        // Regression: 16384 was accepted and advertised, and GetMaps over 8193 refused.
        ("large.toml", "[server]\nmax_size = 10000\n", "max_size = 10000: must be 1 to 8193"),
        ("memory.toml", "[cache]\nmemory_mb = 0\n", "[cache] memory_mb = 0: must be 16 to 1048576"),
        ("bound.toml", "[tile_cache]\nmax_size = 0\n", "[tile_cache] max_size must be more than 0 bytes"),
        ("bound_unit.toml", "[tile_cache]\nmax_size = \"20 GB of tiles\"\n", "not a size: \"20 GB of tiles\""),
        ("bound_kind.toml", "[tile_cache]\nmax_size = true\n", "not a size (e.g."),
        ("locks.toml", "[tile_cache]\nlock_ttl_s = 0.001\n", "[tile_cache] lock_ttl_s = 0.001: must be 1 to 86400"),
        ("trims.toml", "[tile_cache]\ntrim_interval_s = 5\n", "[tile_cache] trim_interval_s = 5: must be 60 to 86400"),
        ("trims_nan.toml", "[tile_cache]\ntrim_interval_s = nan\n", "trim_interval_s = NaN: must be 60 to 86400"),
        ("url.toml", "[server]\npublic_url = \"example.org\"\n", "public_url = \"example.org\": must start with"),
        (
            "classes.toml",
            "[dem]\npath = \"x.hgt\"\n[landcover]\nkind = \"classes\"\npath = \"c.tif\"\n",
            "[[landcover.classes]]",
        ),
        (
            "foreign.toml",
            "[landcover]\nkind = \"percent\"\npath = \"c.tif\"\nclose = \"DE\"\n",
            "[landcover] close does not apply to kind \"percent\"",
        ),
        (
            "foreign_default.toml",
            "[landcover]\nkind = \"percent\"\npath = \"c.tif\"\nblur_radius_px = 1\n",
            "[landcover] blur_radius_px does not apply to kind \"percent\"",
        ),
        (
            "foreign_linear.toml",
            "[landcover]\nkind = \"map\"\nfull_at = 50\n",
            "[landcover] full_at does not apply to kind \"map\"",
        ),
        ("proxy.toml", "[[forest]]\nname = \"pine\"\nproxy = \"pine.tif\"\n", "pine.tif: cannot open"),
        ("lidar.toml", "[[forest]]\nname = \"pine\"\nlidar = [\"pine.laz\"]\n", "pine.laz: cannot open"),
        (
            "resolution.toml",
            "[[forest]]\nname = \"pine\"\nproxy = \"p.tif\"\nresolution_m = 0.25\n",
            "resolution_m applies to lidar files, and none are given",
        ),
        (
            "both.toml",
            "[[forest]]\nname = \"pine\"\nproxy = \"p.tif\"\nlidar = [\"p.laz\"]\n",
            "a proxy or lidar files, not both",
        ),
        (
            "unknown_type.toml",
            "[landcover]\nkind = \"map\"\nforest = \"oak\"\n[[forest]]\nname = \"pine\"\n",
            "forest = \"oak\" names no [[forest]] type",
        ),
        // Regression: these three were taken (an empty range matched nothing,
        // NaN filled like propagate, a long fill ran out of memory).
        (
            "inverted.toml",
            "[landcover]\nkind = \"classes\"\npath = \"c.tif\"\n[[landcover.classes]]\nranges = [[9000, 7000]]\nsurface = \"forest\"\n",
            "the range [9000, 7000] of forest classes is empty",
        ),
        (
            "nan_fill.toml",
            "[dem]\nnodata = { policy = \"constant\", value = nan }\n",
            "[dem] nodata: value = NaN: must be a finite height",
        ),
        (
            "far_fill.toml",
            "[dem]\nnodata = { policy = \"fill\", max_distance_px = 100000 }\n",
            "max_distance_px = 100000: must be 1 to 2048",
        ),
        (
            "typed_water.toml",
            "[landcover]\nkind = \"classes\"\npath = \"c.tif\"\n[[landcover.classes]]\nvalues = [1]\nsurface = \"water\"\nforest = \"pine\"\n[[forest]]\nname = \"pine\"\n",
            "forest = \"pine\" on water classes",
        ),
    ];
    for (name, text, needle) in cases {
        let path = dir.join(name);
        std::fs::write(&path, text).expect("write");
        let err = sylva::config::load(Some(&path)).expect_err(name).to_string();
        assert!(err.contains(needle), "{name}: {err}");
        assert!(err.contains(name) || err.contains(needle), "{name}: {err}");
    }
    // A geocentric CRS is no map (regression: read as one, bounds near 86° E, 0° N).
    let geocentric = dir.join("geocentric.toml");
    let text = format!("[dem]\npath = {:?}\ncrs = \"EPSG:4978\"\n", common::data("rmnp/rmnp-dem.tif"));
    std::fs::write(&geocentric, text).unwrap();
    let err = sylva::config::load(Some(&geocentric)).expect_err("geocentric").to_string();
    assert!(err.contains("EPSG:4978 cannot be used: geocentric"), "{err}");
    // A picture is no DEM.
    let picture = dir.join("picture.toml");
    std::fs::write(&picture, format!("[dem]\npath = {:?}\n", common::data("rmnp/rmnp-rgb.tif"))).unwrap();
    let err = sylva::config::load(Some(&picture)).expect_err("a picture").to_string();
    assert!(err.contains("picture.toml: [dem] path: ") && err.contains("has 3 bands; a DEM has one"), "{err}");
    // Nor is it a percentage of cover.
    let rgb_cover = dir.join("rgb_cover.toml");
    let (dem, rgb) = (common::data("rmnp/rmnp-dem.tif"), common::data("rmnp/rmnp-rgb.tif"));
    std::fs::write(&rgb_cover, format!("[dem]\npath = {dem:?}\n[landcover]\nkind = \"percent\"\npath = {rgb:?}\n"))
        .unwrap();
    let err = sylva::config::load(Some(&rgb_cover)).expect_err("a picture as cover").to_string();
    assert!(
        err.contains("rgb_cover.toml: [landcover] kind \"percent\" reads one band") && err.contains("has 3"),
        "{err}"
    );
    // Cover of another place covers none of the DEM.
    let elsewhere = dir.join("elsewhere.toml");
    let tcc = common::data("storm_lake/storml_tcc.tif");
    std::fs::write(&elsewhere, format!("[dem]\npath = {dem:?}\n[landcover]\nkind = \"percent\"\npath = {tcc:?}\n"))
        .unwrap();
    let err = sylva::config::load(Some(&elsewhere)).expect_err("cover elsewhere").to_string();
    assert!(err.contains("elsewhere.toml: [landcover] covers none of the DEM"), "{err}");
    // A UTM file read as degrees lies off the globe.
    let metres = dir.join("metres.toml");
    let utm = common::data("storm_lake/storml_elev.tif");
    std::fs::write(&metres, format!("[dem]\npath = {utm:?}\ncrs = \"EPSG:4326\"\n")).unwrap();
    let err = sylva::config::load(Some(&metres)).expect_err("metres as degrees").to_string();
    assert!(
        err.contains("metres.toml: [dem] path: ") && err.contains("EPSG:4326") && err.contains("off the globe"),
        "{err}"
    );
}
