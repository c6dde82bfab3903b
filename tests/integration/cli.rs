//! The `sylva` binary as a user runs it.

use crate::common::{self, TempDir};
use std::process::Command;

fn sylva(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_sylva")).args(args).output().expect("run sylva")
}

#[test]
fn tile_and_build_write_files_that_agree() {
    let dir = TempDir::new("cli");
    let demo = common::demo();
    let b = demo.bounds;
    let t = demo.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), 10);
    let tile_path = dir.join("tile.bil");
    let (level, row, col) = (t.level.to_string(), t.row.to_string(), t.col.to_string());
    let out = sylva(&[
        "tile",
        "--layer",
        "cem",
        "--level",
        &level,
        "--row",
        &row,
        "--col",
        &col,
        "--format",
        "bil32",
        "-o",
        tile_path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s = demo.tiles.sector(t);
    let bbox = format!("{},{},{},{}", s.min_lon, s.min_lat, s.max_lon, s.max_lat);
    let build_path = dir.join("build.bil");
    let out = sylva(&[
        "build",
        "--layer",
        "cem",
        "--bbox",
        &bbox,
        "--width",
        "513",
        "--height",
        "513",
        "--format",
        "bil32",
        "-o",
        build_path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (a, b) = (std::fs::read(tile_path).unwrap(), std::fs::read(build_path).unwrap());
    assert_eq!(a.len(), 513 * 513 * 4);
    assert!(a == b, "the tile and the build of its sector differ");
}

#[test]
fn a_missing_data_file_is_named_and_nothing_is_written() {
    let dir = TempDir::new("cli-missing");
    let config = dir.join("c.toml");
    std::fs::write(&config, "[dem]\npath = \"no/such/dem.tif\"\n").unwrap();
    let out_path = dir.join("x.tif");
    let out = sylva(&[
        "tile",
        "--config",
        config.to_str().unwrap(),
        "--layer",
        "dem",
        "--level",
        "3",
        "--row",
        "1",
        "--col",
        "1",
        "-o",
        out_path.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no/such/dem.tif") && err.contains("cannot open"), "{err}");
    assert!(!out_path.exists());
}

#[test]
fn bad_arguments_are_explained() {
    let dir = TempDir::new("cli-bad-arguments");
    let x = dir.join("x.tif");
    let x = x.to_str().unwrap();
    let out = sylva(&["tile", "--layer", "relief", "--level", "3", "--row", "1", "--col", "1", "-o", x]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.code() == Some(2) && err.contains("'relief'") && err.contains("unknown layer"), "{out:?}");
    let out = sylva(&["build", "--layer", "cem", "--bbox", "1,2,3", "--width", "4", "--height", "4", "-o", x]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("four numbers"), "{out:?}");
    // Options out of their range are usage errors too (exit 2).
    let laz = common::data("lidar_lidR/MixedConifer.laz");
    let tile = ["tile", "--layer", "dem", "-o", x];
    let canopy = ["canopy", "--las", laz.to_str().unwrap(), "-o", x];
    for (args, why) in [
        (&[&tile[..], &["--level", "99", "--row", "1", "--col", "1"]].concat(), "99 is not in 0..=30"),
        (&[&tile[..], &["--level", "3", "--row", "999", "--col", "1"]].concat(), "tile 3/999/1 does not exist"),
        (&[&tile[..], &["--level", "3", "--row", "1", "--col", "1", "--halo", "99999"]].concat(), "0..=512"),
        (&["build", "--layer", "dem", "--width", "0", "--height", "4", "-o", x][..].to_vec(), "1..=8193"),
        (&[&canopy[..], &["--resolution", "0"]].concat(), "positive number"),
        // Regression: these blamed the LiDAR file and exited 1, --crs unnamed.
        (&[&canopy[..], &["--tile-px", "100"]].concat(), "for '--tile-px <TILE_PX>': tiles must be a power of two"),
        (&[&canopy[..], &["--colours", "0"]].concat(), "for '--colours <COLOURS>': 0 is not in 1..=4"),
        (&[&canopy[..], &["--colours", "5"]].concat(), "for '--colours <COLOURS>': 5 is not in 1..=4"),
        (&[&canopy[..], &["--variants", "0"]].concat(), "for '--variants <VARIANTS>': 0 is not in 1..=8"),
        (&[&canopy[..], &["--crs", "foo"]].concat(), "for '--crs <CRS>': crs \"foo\" is not of the form"),
        (&["serve", "--bind", "notanaddr"][..].to_vec(), "must be HOST:PORT"),
        (&["bench", "raycast", "--only", "nonsense"][..].to_vec(), "the settings: [\"linear 30 + 10\""),
    ] {
        let out = sylva(args);
        let err = String::from_utf8_lossy(&out.stderr);
        let blames_input = err.contains("MixedConifer");
        assert!(out.status.code() == Some(2) && err.contains(why) && !blames_input, "{args:?}: {err}");
    }
    assert!(!dir.join("x.tif").exists());
    let out = sylva(&["info"]);
    assert!(out.status.success() && String::from_utf8_lossy(&out.stdout).contains("canopy"));
    // The file and the cause, the cause said once.
    let out = sylva(&["info", "--config", "/no/such/sylva.toml"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/no/such/sylva.toml") && err.matches("No such file").count() == 1, "{err}");
    let valley = common::repo().join("config/paths/demo_valley.toml");
    let never = dir.join("never");
    let fly = |more: &[&str]| {
        let out =
            sylva(&[&["fly", "--path", valley.to_str().unwrap(), "--out", never.to_str().unwrap()], more].concat());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    assert!(fly(&["--budget-ms", "20"]).contains("apply to --lod budget only"));
    assert!(fly(&["--max-level", "99"]).contains("99 is not in 0..=30"));
    assert!(!never.exists());
    // An output may not overwrite an input.
    let config = dir.join("c.toml");
    std::fs::write(&config, "[grid]\n").unwrap();
    let c = config.to_str().unwrap();
    let out = sylva(&["tile", "--config", c, "--layer", "dem", "--level", "1", "--row", "0", "--col", "0", "-o", c]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("is also an input"), "{out:?}");
    assert_eq!(std::fs::read_to_string(&config).unwrap(), "[grid]\n");
}

#[test]
fn no_output_overwrites_a_file_the_configuration_reads() {
    let dir = TempDir::new("cli-clobber-data");
    let dem = dir.join("dem.tif");
    let d = dem.to_str().unwrap();
    let out = sylva(&["build", "--layer", "dem", "--width", "16", "--height", "16", "-o", d]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let bytes = std::fs::read(&dem).unwrap();
    let config = dir.join("c.toml");
    std::fs::write(&config, "[dem]\npath = \"dem.tif\"\n").unwrap();
    let (c, cache) = (config.to_str().unwrap(), dir.join("cache"));
    let runs: [&[&str]; 3] = [
        &["build", "--config", c, "--layer", "dem", "--width", "8", "--height", "8", "-o", d],
        &["tile", "--config", c, "--layer", "dem", "--level", "9", "--row", "0", "--col", "0", "-o", d],
        &["seed", "--config", c, "--levels", "0", "--cache-dir", cache.to_str().unwrap(), "--progress-file", d],
    ];
    for args in runs {
        let out = sylva(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains("dem.tif") && err.contains("is also an input"),
            "{args:?}: {err}"
        );
        assert!(std::fs::read(&dem).unwrap() == bytes, "{args:?} changed the DEM");
    }
}

#[test]
fn a_file_the_user_may_not_write_is_refused_though_its_directory_is_writable() {
    // Regression: the new file was renamed over it (a rename needs only the
    // directory's permission). Root may write any file: as root, the run is
    // nobody's.
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    use std::os::unix::process::CommandExt;
    const NOBODY: u32 = 65534;
    let dir = TempDir::new("cli-read-only");
    std::fs::set_permissions(&dir.0, std::fs::Permissions::from_mode(0o777)).unwrap();
    let out_path = dir.join("ro.tif");
    std::fs::write(&out_path, b"keep").unwrap();
    std::fs::set_permissions(&out_path, std::fs::Permissions::from_mode(0o444)).unwrap();
    let mut run = Command::new(env!("CARGO_BIN_EXE_sylva"));
    run.args(["tile", "--layer", "dem", "--level", "11", "--row", "7758", "--col", "10816", "-o"]).arg(&out_path);
    if std::fs::metadata(&out_path).unwrap().uid() == 0 {
        run.uid(NOBODY).gid(NOBODY);
    }
    let out = run.output().expect("run sylva");
    let err = String::from_utf8_lossy(&out.stderr);
    let refused = out.status.code() == Some(1) && err.contains("ro.tif: cannot write: Permission denied");
    assert!(refused, "{:?}: {err}", out.status);
    assert_eq!(std::fs::read(&out_path).unwrap(), b"keep");
    assert_eq!(std::fs::read_dir(&dir.0).unwrap().count(), 1, "no new file is left beside it");
}

#[test]
fn a_reader_gone_away_is_no_error() {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_sylva")).arg("info").stdout(writer).output().expect("run sylva");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && !err.contains("panicked"), "{:?}: {err}", out.status);
}

#[test]
fn areas_that_do_not_meet_the_region_are_refused_and_polygons_are_clipped_to_it() {
    let dir = TempDir::new("cli-outside");
    let (out, cache) = (dir.join("x.tif"), dir.join("cache"));
    let (o, c) = (out.to_str().unwrap(), cache.to_str().unwrap());
    let far = dir.join("far.geojson");
    std::fs::write(&far, r#"{"type":"Polygon","coordinates":[[[100,6],[101,6],[101,7],[100,7],[100,6]]]}"#).unwrap();
    let runs: [&[&str]; 3] = [
        &["tile", "--layer", "cem", "--level", "11", "--row", "100", "--col", "100", "-o", o],
        &["build", "--layer", "cem", "--width", "8", "--height", "8", "--bbox", "100,6,101,7", "-o", o],
        &["seed", "--levels", "8-9", "--cache-dir", c, "--coverage", far.to_str().unwrap(), "--dry-run"],
    ];
    for args in runs {
        let run = sylva(args);
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success() && err.contains("does not meet the region"), "{args:?}: {err}");
    }
    assert!(!out.exists());
    // A polygon reaching past the region seeds what a box over it would.
    let near = dir.join("near.geojson");
    std::fs::write(&near, r#"{"type":"Polygon","coordinates":[[[9,46],[10.1,46],[10.1,47],[9,47],[9,46]]]}"#).unwrap();
    let dry = |area: &[&str]| {
        let run = sylva(&[&["seed", "--levels", "8-12", "--cache-dir", c, "--dry-run"], area].concat());
        String::from_utf8_lossy(&run.stdout).lines().skip(1).collect::<Vec<_>>().join("\n")
    };
    let (polygon, bbox) = (dry(&["--coverage", near.to_str().unwrap()]), dry(&["--bbox", "9,46,10.1,47"]));
    assert!(polygon.contains("all") && polygon == bbox, "{polygon}\n{bbox}");
}

#[test]
fn benchmarks_refuse_a_named_region_or_an_output_they_cannot_use_before_running() {
    for bench in ["pipeline", "lod", "sse"] {
        let out = sylva(&["bench", bench, "--rmnp", "/no/such/rmnp.toml"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains("/no/such/rmnp.toml"), "bench {bench}: {err}");
    }
    let out = sylva(&["bench", "raycast", "--size", "8x8", "--plot", "/no/such/dir/plot.png"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("/no/such/dir: no such directory"), "{err}");
    // Regression: these exited 0 with "(no plot: No such file or
    // directory (os error 2))" and an inline note.
    let out = sylva(&["bench", "lod", "--frames", "10", "--plots", "/no/such/plots"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.code() == Some(1) && err.contains("/no/such/plots: no such directory"), "{err}");
    let out = sylva(&["bench", "lod", "--frames", "10", "--flights", "/no/such/flight"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.code() == Some(1) && err.contains("--flights /no/such/flight/stats.csv: No such file"), "{err}");
}

#[test]
fn ctrl_c_during_a_build_ends_it_at_once_and_writes_nothing() {
    // Regression: the signal ended the process mid-write, leaving
    // `NAME.partial` (up to 268 MB); then it waited for the computation to
    // end, minutes for a large canopy proxy.
    let dir = TempDir::new("cli-build-signal");
    let out = dir.join("big.tif");
    let build = Command::new(env!("CARGO_BIN_EXE_sylva"))
        .args(["build", "--layer", "max32", "--width", "8193", "--height", "8193", "-o", out.to_str().unwrap()])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert!(Command::new("kill").arg("-INT").arg(build.id().to_string()).status().unwrap().success());
    let signalled = std::time::Instant::now();
    let output = build.wait_with_output().unwrap();
    assert!(signalled.elapsed().as_secs_f64() < 3.0, "ended {:?} after the signal", signalled.elapsed());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("interrupted by signal 2; nothing written"), "{stderr}");
    let left: Vec<_> = std::fs::read_dir(&dir.0).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn a_second_ctrl_c_while_a_build_writes_abandons_its_output() {
    // Regression: the 268 MB were written in one write(2), during which
    // both signals merged into one; the output was written and replaced
    // the old one.
    let dir = TempDir::new("cli-build-abandon");
    let out = dir.join("big.tif");
    std::fs::write(&out, "the old output").unwrap();
    let mut build = Command::new(env!("CARGO_BIN_EXE_sylva"))
        .args(["build", "--layer", "max32", "--width", "8193", "--height", "8193", "-o", out.to_str().unwrap()])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // A partial file with bytes in it: the empty one `outputs::check` makes
    // and removes at once (may the output's directory be written?) comes
    // before the product is computed.
    let writing = || {
        std::fs::read_dir(&dir.0)
            .unwrap()
            .flatten()
            .any(|e| e.file_name().to_string_lossy().ends_with(".partial") && e.metadata().is_ok_and(|m| m.len() > 0))
    };
    while !writing() {
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let pid = build.id().to_string();
    let interrupt = || assert!(Command::new("kill").arg("-INT").arg(&pid).status().unwrap().success());
    interrupt();
    // The second once the first was taken (two at once may merge into one).
    use std::io::BufRead;
    let mut lines = std::io::BufReader::new(build.stderr.take().unwrap()).lines();
    let first = lines.next().unwrap().unwrap();
    assert!(first.contains("finishing the outputs (a second signal abandons them)"), "{first}");
    interrupt();
    let stderr = lines.map(Result::unwrap).collect::<Vec<_>>().join("\n");
    assert_eq!(build.wait().unwrap().code(), Some(130), "{stderr}");
    assert!(stderr.contains("the outputs not yet in place abandoned"), "{stderr}");
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "the old output");
    let left: Vec<_> = std::fs::read_dir(&dir.0).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left.len(), 1, "{left:?}");
}

#[test]
fn an_error_said_to_a_stderr_nobody_reads_still_exits_1() {
    // Regression: eprintln! panicked on the closed pipe (exit 101).
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let status = Command::new(env!("CARGO_BIN_EXE_sylva"))
        .args(["info", "--config", "/no/such/config.toml"])
        .stderr(writer)
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(1));
}

#[test]
fn a_benchmark_plot_that_cannot_be_written_loses_no_table() {
    // The real-data region's plot is written after its flyovers: a
    // directory in its place fails only then, and the tables printed
    // before it stay printed.
    let dir = TempDir::new("cli-lod-plot");
    std::fs::create_dir_all(dir.join("lod_rmnp.png")).unwrap();
    let out = sylva(&["bench", "lod", "--frames", "3", "--plots", dir.0.to_str().unwrap()]);
    let (text, err) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.code() == Some(1) && err.contains("lod_rmnp.png: is a directory"), "{err}");
    assert!(text.contains("plot: ") && text.contains("lod_demo.png"), "{text}");
    assert!(text.matches("Splitting: error against run time").count() == 2, "{text}");
}

#[test]
fn geotiff_output_has_the_geotransform_gdal_reads() {
    let dir = TempDir::new("cli-gdal");
    let path = dir.join("t.tif");
    let out = sylva(&[
        "build",
        "--layer",
        "dem",
        "--bbox",
        "10.1,46.35,10.15,46.4",
        "--width",
        "101",
        "--height",
        "51",
        "-o",
        path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let info = Command::new("gdalinfo").arg(&path).output().expect("gdalinfo (apt-get install gdal-bin)");
    let text = String::from_utf8_lossy(&info.stdout);
    // Pixel centres on the samples: origin half a step outside the box.
    assert!(text.contains("Size is 101, 51"), "{text}");
    assert!(text.contains("Origin = (10.099750000000000,46.400500000000001)"), "{text}");
    assert!(text.contains("Pixel Size = (0.000500000000000,-0.001000000000000)"), "{text}");
    assert!(text.contains("NoData Value=-32768"), "{text}");
}

#[test]
fn bench_raycast_elsewhere_than_the_repository_root_says_where_to_run_it() {
    // Regression: run elsewhere it said "docs: no such directory to write
    // into", or with --plot "config/paths/demo_valley.toml: No such file".
    let dir = TempDir::new("cli-raycast-elsewhere");
    let raycast = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_sylva"))
            .args(["bench", "raycast"])
            .args(args)
            .current_dir(&dir.0)
            .output()
            .expect("run sylva");
        assert_eq!(out.status.code(), Some(1));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    for args in [&[][..], &["--plot", "plot.png"][..]] {
        let err = raycast(args);
        assert!(
            err.contains("config/paths/demo_valley.toml: no such file")
                && err.contains("camera paths from config/paths/ in the current directory")
                && err.contains("run it from the repository root"),
            "{args:?}: {err}"
        );
    }
    // With the paths there, the default plot's directory is missing (the
    // documented run, the default size: a partial run writes no plot).
    let paths = dir.join("config/paths");
    std::fs::create_dir_all(&paths).unwrap();
    for entry in std::fs::read_dir(common::repo().join("config/paths")).unwrap() {
        let file = entry.unwrap().path();
        std::fs::copy(&file, paths.join(file.file_name().unwrap())).unwrap();
    }
    let err = raycast(&[]);
    assert!(err.contains("docs: no such directory") && err.contains("give --plot FILE"), "{err}");
}

#[test]
fn a_build_with_no_data_says_so() {
    // An all-nodata DEM (a GeoTIFF of NaN over part of the demo) gives a
    // file of nodata: said, not silent.
    use sylva::encode::{self, Quantization, Samples};
    let dir = TempDir::new("cli-no-data");
    let grid = sylva::grid::BBox::parse("10.0,46.3,10.1,46.4").unwrap().area_grid(16, 16).unwrap();
    let nan = sylva::raster::Raster::filled(16, 16, f32::NAN);
    let dem = encode::encode(
        sylva::cem::Layer::Dem,
        Samples::Float(&nan),
        &grid,
        encode::Format::Tiff,
        Quantization::PNG16_HEIGHTS,
    )
    .unwrap();
    std::fs::write(dir.join("nan.tif"), dem.bytes).unwrap();
    let config = dir.join("nan.toml");
    std::fs::write(&config, "[dem]\npath = \"nan.tif\"\n").unwrap();
    let out = dir.join("out.tif");
    let args = ["build", "--config", config.to_str().unwrap(), "--layer", "cem", "--width", "8", "--height", "8"];
    let run = sylva(&[&args[..], &["-o", out.to_str().unwrap()]].concat());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success() && err.contains("warning: every sample is nodata"), "{err}");
}

#[test]
fn flight_options_out_of_range_are_refused_before_any_work() {
    // Regression: `--hold-ms inf` held the first frame for ever. Each is a
    // usage error, exit 2 (some were 1).
    for (args, why) in [
        (&["--hold-ms", "inf"][..], "not 0 to 60000 milliseconds"),
        (&["--hold-ms=-1"][..], "not 0 to 60000 milliseconds"),
        (&["--traversal", "linear:0"][..], "STEPS 1 to 4096"),
        (&["--size", "0x10"][..], "each 1 to 16384"),
        (&["--lod", "fastest"][..], "possible values: sse, budget"),
        (&["--lod", "budget", "--budget-ms", "0"][..], "not a positive number of milliseconds"),
        (&["--geomorph"][..], "apply to --lod budget only"),
    ] {
        let out = sylva(&[&["fly", "--path", "nowhere.toml", "--out", "/nonexistent/out"][..], args].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.code() == Some(2) && err.contains(why), "{args:?}: {:?} {err}", out.status);
    }
    let out = sylva(&["bench", "raycast", "--size", "640"]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
}
