//! `sylva fly` as a user runs it, in process and against a `sylva serve`;
//! tiles over HTTP equal tiles computed in process.

use crate::common::{self, TempDir};
use crate::http::Server;
use std::path::PathBuf;
use std::sync::Arc;
use sylva::client::http::HttpSource;
use sylva::client::source::{RegionSource, TileSource};
use sylva::grid::TileId;

pub fn fly(args: &[&str], out: &std::path::Path) -> String {
    let (stdout, stderr) = fly_with(args, out, &[]);
    assert!(stderr.is_empty(), "a flight that went well logged:\n{stderr}");
    stdout
}

/// `sylva fly` with more environment `variables`: what it printed and logged.
fn fly_with(args: &[&str], out: &std::path::Path, variables: &[(&str, &str)]) -> (String, String) {
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_sylva"))
        .arg("fly")
        .args(args)
        .arg("--out")
        .arg(out)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .envs(variables.iter().copied())
        .output()
        .expect("run sylva fly");
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "sylva fly failed: {stderr}");
    (String::from_utf8_lossy(&output.stdout).into_owned(), stderr)
}

/// The rows of `stats.csv` as name → value maps.
pub fn stats(out: &std::path::Path) -> Vec<std::collections::HashMap<String, String>> {
    let text = std::fs::read_to_string(out.join("stats.csv")).expect("stats.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    lines.map(|l| header.iter().map(|h| h.to_string()).zip(l.split(',').map(str::to_string)).collect()).collect()
}

#[test]
fn a_flight_over_the_demo_writes_frames_and_statistics() {
    let dir = TempDir::new("fly-demo");
    let path = common::repo().join("config/paths/demo_valley.toml");
    let summary = fly(&["--path", path.to_str().unwrap(), "--frames", "3", "--size", "96x64"], &dir.join("out"));
    assert!(summary.contains("3 frames"), "{summary}");
    let rows = stats(&dir.join("out"));
    assert_eq!(rows.len(), 3);
    for (k, row) in rows.iter().enumerate() {
        let png = dir.join("out").join(format!("frame_{k:05}.png"));
        let img = image::open(&png).expect("a PNG frame").to_rgba8();
        assert_eq!(img.dimensions(), (96, 64));
        let number = |c: &str| row[c].parse::<f64>().unwrap_or_else(|_| panic!("{c} = {:?}", row[c]));
        assert!(number("tiles") >= 1.0 && number("ray_pixels") > 100.0, "{row:?}");
        assert!(number("view_fetches_mean") > 0.0 && number("view_fetches_max") >= number("view_fetches_mean"));
        assert!(!row["levels"].is_empty());
        // The walk alone is timed, within the CPU's time of the frame.
        assert!(number("selection_ms") > 0.0 && number("selection_ms") < number("cpu_ms"), "{row:?}");
        assert!(number("error_px") >= 2.0 && row["budget_ms"].is_empty(), "{row:?}");
        // Tens of metres over the valley floor (~900 m) and its forest.
        assert!((10.0..500.0).contains(&number("clearance_m")), "{row:?}");
        // Low over a valley: the ground fills the lower half of the frame.
        let ground = img.pixels().skip(96 * 40).filter(|p| p.0[..3] != [158, 189, 224]).count();
        assert!(ground > 96 * 20, "frame {k} shows the ground");
    }
}

#[test]
fn a_flight_on_opengl_binds_its_texture_arrays_as_arrays() {
    let dir = TempDir::new("fly-gl");
    let path = common::repo().join("config/paths/demo_valley.toml");
    let args = ["--path", path.to_str().unwrap(), "--frames", "2", "--size", "64x48", "--no-frames"];
    // wgpu's GL backend guesses a texture's view from its layers, and logs
    // when a binding contradicts its guess (a one-layer array read as 2-D).
    let variables = [("WGPU_BACKEND", "gl"), ("RUST_LOG", "wgpu_hal=error")];
    let (summary, log) = fly_with(&args, &dir.join("out"), &variables);
    assert!(summary.contains("2 frames"), "{summary}");
    assert!(!log.contains("view dimension"), "{log}");
}

#[test]
fn tiles_over_http_equal_tiles_in_process_and_a_flight_uses_them() {
    let dir = TempDir::new("fly-http");
    let server = Server::start(None, &dir.join("cache"));
    let remote = HttpSource::connect(&server.base).expect("connect");
    let local = RegionSource::new(Arc::new(common::demo()));
    assert_eq!(remote.grid(), local.grid());
    let id = local.grid().tile_containing(10.12, 46.37, 10);
    let (a, b) = (remote.fetch(id, 8).unwrap().expect("data"), local.fetch(id, 8).unwrap().expect("data"));
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a.cem), bits(&b.cem));
    assert_eq!(bits(&a.dem), bits(&b.dem));
    assert_eq!(a.surface, b.surface);
    assert_eq!(a.colour, b.colour);
    assert!(remote.bytes_fetched() > 4 * 529 * 529);
    // Far from the region, no data: the server answers 404.
    assert!(remote.fetch(TileId::new(10, 100, 100), 8).unwrap().is_none());

    let path = common::repo().join("config/paths/demo_dive.toml");
    fly(
        &["--server", &server.base, "--path", path.to_str().unwrap(), "--frames", "2", "--size", "64x48"],
        &dir.join("out"),
    );
    let rows = stats(&dir.join("out"));
    assert!(rows.iter().map(|r| r["bytes_fetched"].parse::<u64>().unwrap()).sum::<u64>() > 0, "tiles came over HTTP");
}

#[test]
fn bad_flight_input_is_explained() {
    let dir = TempDir::new("fly-bad");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "fov_deg = 60\n").unwrap();
    let run = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_sylva")).arg("fly").args(args).output().expect("run")
    };
    let out_dir = dir.join("o");
    let o = out_dir.to_str().unwrap();
    let e = run(&["--path", bad.to_str().unwrap(), "--out", o]);
    assert!(!e.status.success() && String::from_utf8_lossy(&e.stderr).contains("bad.toml"));
    let path = common::repo().join("config/paths/demo_valley.toml");
    // An output that cannot be written stops the flight before its first frame.
    std::fs::create_dir_all(out_dir.join("stats.csv")).unwrap();
    let e = run(&["--path", path.to_str().unwrap(), "--out", o, "--frames", "2", "--size", "32x24"]);
    assert!(String::from_utf8_lossy(&e.stderr).contains("stats.csv: is a directory"));
    assert!(!out_dir.join("frame_00000.png").exists(), "no frame was rendered");
    let e = run(&["--path", path.to_str().unwrap(), "--out", o, "--server", "http://127.0.0.1:9"]);
    let said = String::from_utf8_lossy(&e.stderr);
    assert!(said.contains("tiles.json") && said.contains("after 3 attempts"), "{said}");
    assert!(said.contains("attempt=\"1 of 3\""), "each failed try is logged: {said}");
    let model = dir.join("model.json");
    std::fs::write(&model, r#"{"units": 2, "constants_ms": [1, 1, 1, -1, 1, 1, 1, 1]}"#).unwrap();
    let e = run(&[
        "--path",
        path.to_str().unwrap(),
        "--out",
        o,
        "--lod",
        "budget",
        "--cost-model",
        model.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&e.stderr);
    assert!(!e.status.success() && stderr.contains("model.json") && stderr.contains("constant 3"), "{stderr}");
}

#[test]
fn a_flight_never_mixes_with_an_earlier_one_in_its_directory() {
    let dir = TempDir::new("fly-again");
    let out = dir.join("out");
    let valley = common::repo().join("config/paths/demo_valley.toml");
    let dive = common::repo().join("config/paths/demo_dive.toml");
    fly(&["--path", valley.to_str().unwrap(), "--frames", "2", "--size", "32x24"], &out);
    // Refused, and the earlier flight is whole.
    let again = std::process::Command::new(env!("CARGO_BIN_EXE_sylva"))
        .args(["fly", "--path", dive.to_str().unwrap(), "--frames", "1", "--size", "32x24", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(
        !again.status.success() && err.contains("earlier flight's or view's outputs (stats.csv, 2 frames)"),
        "{err}"
    );
    assert_eq!(stats(&out).len(), 2);
    assert!(out.join("frame_00001.png").exists());
    // A run that fails at its first frame (a DEM cut off halfway) leaves
    // the earlier one whole.
    let broken = broken_region(&dir);
    let failed = std::process::Command::new(env!("CARGO_BIN_EXE_sylva"))
        .args(["fly", "--config", broken.to_str().unwrap(), "--path", dive.to_str().unwrap(), "--size", "32x24"])
        .args(["--overwrite", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&failed.stderr);
    assert!(!failed.status.success() && err.contains("half.tif"), "{err}");
    assert_eq!(stats(&out).len(), 2);
    // So does one whose first frame cannot be written (its name a link to a
    // directory).
    let (first, blocker) = (out.join("frame_00000.png"), out.join("blocker"));
    std::fs::create_dir(&blocker).unwrap();
    std::fs::rename(&first, out.join("kept.png")).unwrap();
    std::os::unix::fs::symlink(&blocker, &first).unwrap();
    let unwritable = std::process::Command::new(env!("CARGO_BIN_EXE_sylva"))
        .args(["fly", "--path", dive.to_str().unwrap(), "--frames", "1", "--size", "32x24", "--overwrite", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!unwritable.status.success(), "{}", String::from_utf8_lossy(&unwritable.stderr));
    assert!(String::from_utf8_lossy(&unwritable.stderr).contains("frame_00000.png: is a directory"));
    assert_eq!(stats(&out).len(), 2);
    assert!(out.join("frame_00001.png").exists());
    std::fs::remove_file(&first).unwrap();
    std::fs::remove_dir(&blocker).unwrap();
    std::fs::rename(out.join("kept.png"), &first).unwrap();
    // Replaced whole with --overwrite: no frame of the earlier flight is left.
    fly(&["--path", dive.to_str().unwrap(), "--frames", "1", "--size", "32x24", "--overwrite"], &out);
    assert_eq!(stats(&out).len(), 1);
    assert!(out.join("frame_00000.png").exists() && !out.join("frame_00001.png").exists());
}

#[test]
fn a_flight_that_sees_no_tile_or_flies_under_the_ground_says_so() {
    let dir = TempDir::new("fly-away");
    let away = dir.join("away.toml");
    let text = std::fs::read_to_string(common::repo().join("config/paths/demo_valley.toml")).unwrap();
    // The same flight 70° further west, over the Atlantic.
    std::fs::write(&away, text.replace("lon = 10.", "lon = -60.")).unwrap();
    let summary = fly(&["--path", away.to_str().unwrap(), "--frames", "1", "--size", "32x24"], &dir.join("out"));
    assert!(summary.contains("no frame drew a tile"), "{summary}");
    let home = common::repo().join("config/paths/demo_valley.toml");
    let summary = fly(&["--path", home.to_str().unwrap(), "--frames", "1", "--size", "32x24"], &dir.join("home"));
    assert!(!summary.contains("no frame drew a tile") && !summary.contains("below the ground"), "{summary}");
    // The same flight 1 km lower, under the valley floor.
    let under = dir.join("under.toml");
    std::fs::write(&under, text.replace("height_m = 1", "height_m = ")).unwrap();
    let summary = fly(&["--path", under.to_str().unwrap(), "--frames", "2", "--size", "32x24"], &dir.join("under"));
    assert!(summary.contains("the camera is below the ground in 2 frames (from frame 0"), "{summary}");
}

/// The rows of a `--lod budget` flight of `frames` 96×64 frames along the
/// demo valley under `ms`, written to `out`.
fn budget_flight(
    out: &std::path::Path,
    frames: &str,
    ms: &str,
    more: &[&str],
) -> Vec<std::collections::HashMap<String, String>> {
    let path = common::repo().join("config/paths/demo_valley.toml");
    let args = ["--frames", frames, "--size", "96x64", "--no-frames", "--lod", "budget", "--budget-ms", ms];
    fly(&[&["--path", path.to_str().unwrap()][..], &args[..], more].concat(), out);
    stats(out)
}

#[test]
fn a_flight_under_a_frame_budget_reports_its_predicted_frame_time() {
    let dir = TempDir::new("fly-budget");
    let flight = |ms: &str, name: &str, more: &[&str]| budget_flight(&dir.join(name), "3", ms, more);
    let number = |row: &std::collections::HashMap<String, String>, c: &str| {
        row[c].parse::<f64>().unwrap_or_else(|_| panic!("{c} = {:?}", row[c]))
    };
    // A budget no frame can meet: the coarsest tiles, the overrun reported.
    let tight = flight("0.001", "tight", &[]);
    // A budget every frame meets: refined as far as the GPU cache allows
    // (geomorphing).
    let loose = flight("100000", "loose", &["--geomorph"]);
    for row in tight.iter().chain(&loose) {
        assert!(number(row, "predicted_ms") > 0.0 && number(row, "selection_ms") >= 0.0, "{row:?}");
        assert!(row["error_px"].is_empty() && number(row, "tiles") >= 1.0, "{row:?}");
    }
    for (t, l) in tight.iter().zip(&loose) {
        assert!(number(t, "predicted_ms") > number(t, "budget_ms"), "{t:?}");
        assert!(number(l, "predicted_ms") <= number(l, "budget_ms"), "{l:?}");
        assert!(number(l, "tiles") > number(t, "tiles"), "{t:?} {l:?}");
        assert!(number(l, "candidates") >= number(l, "tiles"), "{l:?}");
        let reached = number(l, "benefit_bound");
        assert!(reached > 0.5 && reached <= 1.0 + 1e-9, "{l:?}");
        // The sun is up: a rich budget buys shadows, a poor one none.
        assert!(number(l, "shadow_steps_mean") > number(t, "shadow_steps_mean"), "{t:?} {l:?}");
    }
}

#[test]
fn a_short_budget_flight_draws_the_trees_its_budget_allows() {
    // Its first selection knows no tile to grow trees on: the groups it did
    // not price share what its budget leaves.
    let dir = TempDir::new("fly-budget-trees");
    let path = common::repo().join("config/paths/demo_valley.toml");
    let flight = |name: &str, more: &[&str]| {
        let args = ["--path", path.to_str().unwrap(), "--frames", "3", "--size", "320x240", "--no-frames"];
        fly(&[&args[..], more].concat(), &dir.join(name));
        stats(&dir.join(name))
    };
    let sse = flight("sse", &[]);
    let loose = flight("loose", &["--lod", "budget", "--budget-ms", "100000"]);
    let tight = flight("tight", &["--lod", "budget", "--budget-ms", "0.001"]);
    let number = |row: &std::collections::HashMap<String, String>, c: &str| row[c].parse::<usize>().unwrap();
    assert!(number(&sse[0], "trees") > 100, "{:?}", sse[0]);
    for ((s, l), t) in sse.iter().zip(&loose).zip(&tight) {
        // Room for all: every tree in reach at full resolution.
        assert_eq!(number(s, "trees") > 0, number(l, "trees") > 0, "{s:?} {l:?}");
        assert_eq!(number(l, "splats"), 24 * number(l, "trees"), "{l:?}");
        assert_eq!(number(t, "splats"), 0, "the budget is spent on the coarsest tiles: {t:?}");
    }
}

#[test]
fn a_calibrated_cost_model_starts_the_next_flight() {
    let dir = TempDir::new("fly-prior");
    let flight = |name: &str, more: &[&str]| budget_flight(&dir.join(name), "6", "50", more);
    let first = flight("first", &[]);
    let saved = dir.join("first/cost_model.json");
    let model = sylva::lod::model::CostModel::from_json(&std::fs::read_to_string(&saved).expect("cost_model.json"))
        .expect("a valid model");
    assert_ne!(model, sylva::lod::model::CostModel::default(), "the flight calibrated its model");
    let second = flight("second", &["--cost-model", saved.to_str().unwrap()]);
    // Frame 1 draws the first selection, priced by the prior alone (frame 0
    // builds the pipelines): the calibrated prior prices it within 2×, or
    // better than the default constants do.
    let error = |rows: &[std::collections::HashMap<String, String>]| {
        let row = &rows[1];
        let measured: f64 = row["gpu_ms"].parse().or_else(|_| row["render_ms"].parse()).unwrap();
        (row["predicted_ms"].parse::<f64>().unwrap() / measured).ln().abs()
    };
    let (before, after) = (error(&first), error(&second));
    assert!(after < before.max(2f64.ln()), "prediction error of frame 1: {before:.2} → {after:.2} (|ln ratio|)");
}

#[test]
fn a_flight_with_rays_in_a_compute_pass_keeps_its_tiles_within_the_gpu_budget() {
    let dir = TempDir::new("fly-compute");
    let path = common::repo().join("config/paths/demo_valley.toml");
    // 69 MiB: ten slots of a demo tile's textures (7,194,168 bytes), nine
    // with its meshes (106,792 bytes more): meshes count.
    let budget_mib = 69.0;
    let args = ["--path", path.to_str().unwrap(), "--frames", "8", "--size", "96x64", "--ray-pass", "compute"];
    // The budget's selection keeps to the slots.
    let more = ["--gpu-budget-mib", "69", "--no-frames", "--lod", "budget", "--budget-ms", "1000"];
    let summary = fly(&[&args[..], &more[..]].concat(), &dir.join("out"));
    assert!(summary.contains("8 frames"), "{summary}");
    let rows = stats(&dir.join("out"));
    let full = rows.iter().filter(|r| r["gpu_bytes"].parse::<f64>().is_ok_and(|b| b > 8.0 * 7_194_168.0)).count();
    assert!(full > 0, "the cache fills");
    for row in rows {
        let number = |c: &str| row[c].parse::<f64>().unwrap_or_else(|_| panic!("{c} = {:?}", row[c]));
        assert!(number("ray_pixels") > 100.0, "{row:?}");
        assert!(number("gpu_bytes") > 0.0 && number("gpu_bytes") <= budget_mib * 1024.0 * 1024.0, "{row:?}");
    }
}

/// `sylva fly` with `args`, writing to `out`, left running.
pub fn spawn_fly(args: &[&str], out: &std::path::Path) -> std::process::Child {
    std::process::Command::new(env!("CARGO_BIN_EXE_sylva"))
        .arg("fly")
        .args(args)
        .arg("--out")
        .arg(out)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run sylva fly")
}

/// Waits for `file` to appear (a minute at most).
pub fn wait_for(file: &std::path::Path) {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while !file.exists() {
        assert!(std::time::Instant::now() < deadline, "{} never appeared", file.display());
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Checks what a flight of `of` frames stopped early left in `out` — its
/// finished frames, stats.csv with a row for each, no partial file — and
/// that it said so; returns how many frames it finished.
fn assert_kept(out: &std::path::Path, of: usize, stderr: &str) -> usize {
    let names: Vec<String> =
        std::fs::read_dir(out).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    let frames = names.iter().filter(|n| n.starts_with("frame_") && n.ends_with(".png")).count();
    assert!(names.iter().all(|n| !n.ends_with(".partial")), "{names:?}");
    assert!((1..of).contains(&frames), "{frames} of {of} frames: {stderr}");
    let rows = stats(out);
    let listed: Vec<&str> = rows.iter().map(|r| r["frame"].as_str()).collect();
    assert_eq!(listed, (0..frames).map(|k| k.to_string()).collect::<Vec<_>>(), "a row for each frame kept");
    for k in 0..frames {
        image::open(out.join(format!("frame_{k:05}.png"))).expect("a whole PNG");
    }
    let said = format!("stopped after {frames} of {of} frames; their frames and stats.csv are in {}", out.display());
    assert!(stderr.contains(&said), "{stderr}");
    frames
}

#[test]
fn a_flight_stopped_by_a_signal_keeps_its_frames_and_their_statistics() {
    // Regression: Ctrl-C or SIGTERM left the frames done and no stats.csv.
    let dir = TempDir::new("fly-signal");
    let path = common::repo().join("config/paths/demo_valley.toml");
    for (signal, status) in [("INT", 130), ("TERM", 143)] {
        let out = dir.join(signal);
        let flight = spawn_fly(&["--path", path.to_str().unwrap(), "--frames", "500", "--size", "32x24"], &out);
        wait_for(&out.join("frame_00001.png"));
        let sent = std::process::Command::new("kill").arg(format!("-{signal}")).arg(flight.id().to_string()).status();
        assert!(sent.unwrap().success());
        let output = flight.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(status), "128 + the signal: {stderr}");
        assert!(stderr.contains("interrupted by signal"), "{stderr}");
        assert_kept(&out, 500, &stderr);
    }
}

#[test]
fn a_flight_whose_server_dies_keeps_its_frames_and_their_statistics() {
    // Regression: a flight whose `sylva serve` was killed left its first
    // frame and no stats.csv.
    let dir = TempDir::new("fly-server-dies");
    let server = Server::start(None, &dir.join("cache"));
    let path = common::repo().join("config/paths/demo_dive.toml");
    let out = dir.join("out");
    let args = ["--server", &server.base, "--path", path.to_str().unwrap(), "--frames", "60", "--size", "32x24"];
    let flight = spawn_fly(&args, &out);
    wait_for(&out.join("frame_00000.png"));
    drop(server);
    let output = flight.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert_kept(&out, 60, &stderr);
}

/// A region whose DEM is cut off halfway (`half.toml` in `dir`): it opens,
/// and its first tiles fail.
fn broken_region(dir: &TempDir) -> std::path::PathBuf {
    let bytes = std::fs::read(common::data("rmnp/rmnp-dem.tif")).unwrap();
    std::fs::write(dir.join("half.tif"), &bytes[..bytes.len() / 2]).unwrap();
    let config = dir.join("half.toml");
    std::fs::write(&config, "[dem]\npath = \"half.tif\"\n").unwrap();
    config
}

#[test]
fn a_flight_that_fails_before_writing_leaves_no_directory() {
    // Regression: a failed flight left the empty --out it had made.
    let dir = TempDir::new("fly-made");
    let path = common::repo().join("config/paths/demo_dive.toml");
    let broken = broken_region(&dir);
    let fail = |out: &std::path::Path| {
        let args = ["--config", broken.to_str().unwrap(), "--path", path.to_str().unwrap(), "--size", "32x24"];
        let output = spawn_fly(&args, out).wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
        assert!(output.status.code() == Some(1) && stderr.contains("half.tif"), "{stderr}");
    };
    fail(&dir.join("new/deeper"));
    assert!(!dir.join("new").exists(), "both directories made went");
    // A directory that was there stays, empty as it was.
    std::fs::create_dir(dir.join("there")).unwrap();
    fail(&dir.join("there"));
    assert_eq!(std::fs::read_dir(dir.join("there")).unwrap().count(), 0);
}

#[test]
fn a_flight_stopped_while_it_starts_leaves_no_directory() {
    // Regression: a signal after the output directory was made and before
    // the first frame killed the flight outright, leaving the directory
    // empty. Whenever the signal comes, nothing is left.
    let dir = TempDir::new("fly-signal-start");
    let path = common::repo().join("config/paths/demo_valley.toml");
    let mut watched = 0;
    for after_ms in [100, 1000, 6000] {
        let (made, out) = (dir.join(&format!("made{after_ms}")), dir.join(&format!("made{after_ms}/out")));
        let flight = spawn_fly(&["--path", path.to_str().unwrap(), "--frames", "500", "--size", "32x24"], &out);
        std::thread::sleep(std::time::Duration::from_millis(after_ms));
        let sent = std::process::Command::new("kill").arg("-INT").arg(flight.id().to_string()).status();
        assert!(sent.unwrap().success());
        let output = flight.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        // Ended by the signal before the watch, or 130 after it.
        assert!(matches!(output.status.code(), None | Some(130)), "{:?}: {stderr}", output.status);
        watched += usize::from(output.status.code() == Some(130));
        let frames_written = out.join("frame_00000.png").exists();
        assert!(frames_written || !made.exists(), "{after_ms} ms: an empty directory is left: {stderr}");
    }
    assert!(watched > 0, "no signal came after the watch began: the test tried nothing");
}

#[test]
fn a_views_saved_frames_are_an_earlier_run_too() {
    // Regression: a view's `view_NNNNN.png` stayed beside the next run's
    // outputs, mixing two runs.
    let dir = TempDir::new("fly-view-frames");
    std::fs::write(dir.join("view_00004.png"), b"png").unwrap();
    let path = common::repo().join("config/paths/demo_dive.toml");
    let args = ["fly", "--path", path.to_str().unwrap(), "--frames", "1", "--size", "32x24", "--out"];
    let refused = std::process::Command::new(env!("CARGO_BIN_EXE_sylva")).args(args).arg(&dir.0).output().unwrap();
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && err.contains("1 frame"), "{err}");
    fly(&["--path", path.to_str().unwrap(), "--frames", "1", "--size", "32x24", "--overwrite"], &dir.0);
    assert!(!dir.join("view_00004.png").exists() && dir.join("frame_00000.png").exists());
}

#[test]
fn an_sse_flight_under_a_tiny_gpu_budget_draws_what_fits() {
    // Regression: under 64 MiB (9 tile slots) or less the coarsest cut did
    // not fit and the flight stopped; it now draws the cut's nearest tiles.
    let dir = TempDir::new("fly-tiny-gpu");
    let path = common::repo().join("config/paths/demo_valley.toml");
    let summary =
        fly(&["--path", path.to_str().unwrap(), "--frames", "2", "--size", "64x48", "--gpu-budget-mib", "16"], &dir.0);
    assert!(summary.contains("in 2 frames the GPU tile cache held no cut at the asked 2 px error"), "{summary}");
    let rows = stats(&dir.0);
    assert_eq!(rows.len(), 2);
    for row in rows {
        let tiles: usize = row["tiles"].parse().unwrap();
        assert!((1..=2).contains(&tiles), "16 MiB holds 2 tiles: {row:?}");
    }
}

/// A DEM of `w × h` samples of `step` degrees, the north-west one's
/// centre at `(lon0, lat0)`, as `NAME.tif` in `dir`; its configuration,
/// `NAME.toml`.
fn geographic_region(
    dir: &TempDir,
    name: &str,
    (lon0, lat0): (f64, f64),
    (w, h): (usize, usize),
    step: f64,
) -> PathBuf {
    use sylva::grid::{Axis, SampleGrid};
    let grid = SampleGrid { lon: Axis::degrees(lon0, step, 0, w), lat: Axis::degrees(lat0, -step, 0, h) };
    let dem =
        sylva::raster::Raster::from_fn(w, h, |x, y| 400.0 + 300.0 * (x as f32 * 0.2).sin() * (y as f32 * 0.15).cos());
    let tiff = sylva::encode::geotiff::write(sylva::encode::Samples::Float(&dem), &grid).expect("GeoTIFF");
    std::fs::write(dir.join(&format!("{name}.tif")), tiff).unwrap();
    let config = dir.join(&format!("{name}.toml"));
    std::fs::write(&config, format!("[dem]\npath = \"{name}.tif\"\n")).unwrap();
    config
}

/// A path of one key looking down from `height_m` above `(lon, lat)`.
fn looking_down(dir: &TempDir, (lon, lat): (f64, f64), height_m: f64) -> PathBuf {
    let path = dir.join("down.toml");
    let key =
        format!("t = 0.0\nlon = {lon}\nlat = {lat}\nheight_m = {height_m}\nheading_deg = 0.0\npitch_deg = -89.0\n");
    std::fs::write(&path, format!("fov_deg = 40\n[[key]]\n{key}")).unwrap();
    path
}

#[test]
fn a_flight_over_a_region_across_the_antimeridian_draws_both_sides() {
    // Regression: tiles west of 180° were compared with the region's bounds
    // (east 180.5°) unturned and never drawn; the frame's east half was sky.
    let dir = TempDir::new("fly-across");
    let config = geographic_region(&dir, "across", (179.5025, -16.0025), (200, 200), 0.005);
    let path = looking_down(&dir, (180.0, -16.5), 20_000.0);
    for lod in ["sse", "budget"] {
        let out = dir.join(lod);
        let (c, p) = (config.to_str().unwrap(), path.to_str().unwrap());
        fly(&["--config", c, "--path", p, "--frames", "1", "--size", "64x48", "--lod", lod], &out);
        let frame = out.join("frame_00000.png");
        let (west, east) = (common::ground_share(&frame, 0.0..0.5), common::ground_share(&frame, 0.5..1.0));
        assert!(west > 0.99 && east > 0.99, "--lod {lod}: ground on {west} of the west half, {east} of the east");
    }
}

#[test]
fn a_flight_above_a_pole_draws_the_whole_view_with_a_small_gpu_cache() {
    // Regression: 40 km above the South Pole the GPU cache held the 73
    // nearest of the 80 tiles around the pole the selection asked for,
    // and the sky showed through a wedge; coarser levels now fit it whole.
    let dir = TempDir::new("fly-pole");
    let config = geographic_region(&dir, "cap", (-179.75, -87.25), (720, 6), 0.5);
    let path = looking_down(&dir, (0.0, -90.0), 40_000.0);
    for lod in ["sse", "budget"] {
        let out = dir.join(lod);
        let (c, p) = (config.to_str().unwrap(), path.to_str().unwrap());
        let args =
            ["--config", c, "--path", p, "--frames", "1", "--size", "64x48", "--lod", lod, "--gpu-budget-mib", "256"];
        let (summary, _) = fly_with(&args, &out, &[]);
        let ground = common::ground_share(&out.join("frame_00000.png"), 0.0..1.0);
        assert!(ground > 0.99, "--lod {lod}: ground on {ground} of the frame; {summary}");
    }
}
