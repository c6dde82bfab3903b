//! `sylva seed` as an operator runs it: seeded tiles are the server's cache
//! hits, byte for byte, World Wind's, the XYZ/WMTS sets' and Cesium's; dry runs count what a seed writes and polygons prune
//! it; a seeder killed with SIGKILL resumes to the same cache (and its dry
//! run counts what is left) with no temporary file of the killed one left,
//! and a wait for a lock it left is explained; one stopped with Ctrl-C
//! leaves no lock; a second job on the same progress file is refused; a
//! source that fails for some tiles gets them retried, listed and re-run
//! from the list; uniform tiles are stored once; bad input is named.

use crate::common::{self, TempDir};
use crate::http::Server;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};
use sylva::cache::{DirStore, Lookup, TileStore};
use sylva::server::products::{self, Encoding, Product};
use sylva::server::wms::request::MapLayer;

/// `sylva seed ARGS` run in `dir` (where its progress and failed files go).
pub fn seed(dir: &Path, args: &[&str]) -> Output {
    seed_command(dir, args).output().expect("run sylva seed")
}

/// The command of [`seed`], not started.
pub fn seed_command(dir: &Path, args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_sylva"));
    cmd.current_dir(dir).arg("seed").arg("--progress").arg("plain").args(args);
    cmd
}

/// [`seed`] started, once it has saved its progress (`seed-progress.json`
/// in `dir`) and is still running; its stderr to `stderr`.
fn seed_until_progress(dir: &Path, args: &[&str], stderr: Stdio) -> std::process::Child {
    let mut child = seed_command(dir, args).stdout(Stdio::null()).stderr(stderr).spawn().expect("run sylva seed");
    let (progress, start) = (dir.join("seed-progress.json"), Instant::now());
    while !progress.exists() {
        assert!(child.try_wait().unwrap().is_none(), "the seed finished before it saved its progress");
        assert!(start.elapsed() < Duration::from_secs(120), "no progress file");
        std::thread::sleep(Duration::from_millis(10));
    }
    child
}

/// Asserts success and returns stdout.
pub fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{:?}\nstdout: {}\nstderr: {}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The number before `what` in a seed summary, e.g. "12 from their children".
pub fn count(summary: &str, what: &str) -> u64 {
    let before = summary.split(what).next().unwrap_or("");
    before
        .rsplit(|c: char| !c.is_ascii_digit())
        .find(|w| !w.is_empty())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no count of {what:?} in {summary:?}"))
}

/// Every tile entry of a directory cache (key → payload), each checked: a
/// truncated or corrupt entry fails the test. Temporaries and locks are not
/// entries.
pub fn tiles(cache: &Path) -> BTreeMap<String, Vec<u8>> {
    let store = DirStore::new(cache);
    let mut out = BTreeMap::new();
    for path in walk(cache) {
        let key = path.strip_prefix(cache).unwrap().to_string_lossy().into_owned();
        let name = path.file_name().unwrap().to_string_lossy();
        if name.starts_with('.') || name.ends_with(".lock") {
            continue;
        }
        match store.get(&key).unwrap() {
            Lookup::Hit(s) => out.insert(key, s.bytes),
            other => panic!("{key}: {other:?}: a damaged tile in the cache"),
        };
    }
    out
}

/// Every file under `dir`, recursively.
pub fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = entry.path();
        if entry.file_type().is_ok_and(|t| t.is_dir()) { out.extend(walk(&p)) } else { out.push(p) }
    }
    out
}

/// `version/layer/level/row/row_col.ext` → the server's product and URL path.
pub fn product_of(key: &str) -> Option<(Product, String)> {
    let parts: Vec<&str> = key.split('/').collect();
    let [_, layer, level, row, file] = parts[..] else { return None };
    let (stem, ext) = file.split_once('.')?;
    let col = stem.split_once('_')?.1;
    let layer = sylva::cem::Layer::parse(layer)?;
    let format = match ext {
        "bil" => sylva::encode::Format::Bil16,
        "bil32" => sylva::encode::Format::Bil32,
        "png" => sylva::encode::Format::Png16,
        _ => sylva::encode::Format::Tiff,
    };
    let id = sylva::grid::TileId::new(level.parse().ok()?, row.parse().ok()?, col.parse().ok()?);
    let product = Product::Tile { layer: MapLayer::Data(layer), id, halo: 0, encoding: Encoding::Data(format) };
    Some((product, format!("/tiles/{}/{level}/{row}/{stem}.{ext}", layer.name())))
}

/// The rmnp configuration, copied into `dir` with absolute data paths and
/// `extra` appended (e.g. a `[tile_cache]` table).
pub fn rmnp_config(dir: &TempDir, name: &str, extra: &str) -> PathBuf {
    let text = std::fs::read_to_string(common::repo().join("config/examples/rmnp.toml")).unwrap();
    let data = common::data("rmnp").parent().unwrap().display().to_string();
    let path = dir.join(name);
    std::fs::write(&path, format!("{}\n{extra}\n", text.replace("../../../shared/data", &data))).unwrap();
    path
}

/// Seed arguments: `config`, `cache`, `layers` at `levels`, then `extra`.
pub fn job_args(config: &Path, cache: &Path, layers: &str, levels: &str, extra: &[&str]) -> Vec<String> {
    let head =
        ["--config", &config.display().to_string(), "--cache-dir", &cache.display().to_string()].map(String::from);
    let tail = ["--layers", layers, "--levels", levels].into_iter().chain(extra.iter().copied()).map(String::from);
    head.into_iter().chain(tail).collect()
}

/// `&str`s of owned arguments.
pub fn strs(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}

/// The "all" row of a dry run: (tiles, files).
fn dry_total(out: &str) -> (u64, u64) {
    let row = out
        .lines()
        .find(|l| l.split('|').nth(1).is_some_and(|cell| cell.trim() == "all"))
        .unwrap_or_else(|| panic!("{out}"));
    let cells: Vec<u64> = row.split('|').filter_map(|c| c.trim().parse().ok()).collect();
    (cells[0], cells[1])
}

#[test]
fn seeded_tiles_are_cache_hits_identical_to_on_demand_tiles() {
    let dir = TempDir::new("seed-hits");
    let config = rmnp_config(&dir, "rmnp.toml", "[tile_cache]\nlock_ttl_s = 2");
    let cache = dir.join("cache");
    let owned = job_args(&config, &cache, "dem,cem", "6-9", &["--formats", "bil16,png16"]);
    let args = strs(&owned);
    let (_, files) = dry_total(&ok(&seed(&dir.0, &[&args[..], &["--dry-run"]].concat())));
    let run = seed(&dir.0, &args);
    let summary = ok(&run);
    assert!(count(&summary, "from their children") > 0, "{summary}");
    // Off a terminal, progress is plain log lines with the rate and the ETA.
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(log.lines().any(|l| l.starts_with("seed: ") && l.contains("files/s, ETA")), "{log}");
    let seeded = tiles(&cache);
    assert_eq!(seeded.len() as u64, files);
    // Byte-identical to what the server computes on demand (parents built
    // from their children included).
    let region = sylva::config::load(Some(&config)).unwrap();
    for (key, bytes) in &seeded {
        let (product, _) = product_of(key).unwrap_or_else(|| panic!("{key}"));
        assert!(products::compute(&region, &product).unwrap().bytes == *bytes, "{key} differs from the on-demand tile");
    }
    // The server answers every one from the cache.
    let server = Server::start(Some(&config), &cache);
    for (key, bytes) in &seeded {
        let (_, path) = product_of(key).unwrap();
        let reply = server.get(&path);
        assert_eq!(reply.status, if bytes.is_empty() { 404 } else { 200 }, "{path}");
        assert!(reply.body == *bytes, "{path}");
    }
    assert_eq!(server.metric("sylva_tile_computations_total"), 0.0);
    assert_eq!(server.metric("sylva_tile_cache_total{result=\"hit\"}"), seeded.len() as f64);
}

#[test]
fn dry_runs_count_what_a_seed_writes_and_polygons_with_holes_prune() {
    let dir = TempDir::new("seed-dry");
    let config = rmnp_config(&dir, "rmnp.toml", "");
    let cfg = config.to_str().unwrap();
    let (bbox_tiles, _) =
        dry_total(&ok(&seed(&dir.0, &["--config", cfg, "--layers", "dem", "--levels", "6-10", "--dry-run"])));
    // A triangle over the region with a square hole.
    let geojson = dir.join("area.geojson");
    std::fs::write(
        &geojson,
        r#"{"type":"Feature","properties":{},"geometry":{"type":"Polygon","coordinates":[
        [[-105.9,40.17],[-105.5,40.17],[-105.9,40.55],[-105.9,40.17]],
        [[-105.85,40.2],[-105.75,40.2],[-105.75,40.3],[-105.85,40.3],[-105.85,40.2]]]}}"#,
    )
    .unwrap();
    let area = ["--config", cfg, "--layers", "dem", "--levels", "6-10", "--coverage", geojson.to_str().unwrap()];
    let (polygon_tiles, files) = dry_total(&ok(&seed(&dir.0, &[&area[..], &["--dry-run"]].concat())));
    assert!(polygon_tiles < bbox_tiles * 2 / 3, "{polygon_tiles} of {bbox_tiles}");
    let cache = dir.join("cache");
    ok(&seed(&dir.0, &[&area[..], &["--cache-dir", cache.to_str().unwrap()]].concat()));
    let seeded = tiles(&cache);
    assert_eq!(seeded.len() as u64, files);
    // Nothing inside the hole at level 10: a tile whose centre is there.
    let hole = sylva::grid::TileGrid::new(36.0, 513).unwrap().tile_containing(-105.8, 40.25, 10);
    assert!(!seeded.keys().any(|k| k.ends_with(&format!("dem/10/{}/{}_{}.bil", hole.row, hole.row, hole.col))));
}

#[test]
fn bad_input_is_named_with_the_problem() {
    let dir = TempDir::new("seed-bad");
    let geojson = dir.join("points.geojson");
    std::fs::write(&geojson, r#"{"type":"Point","coordinates":[1,2]}"#).unwrap();
    let redis = dir.join("redis.toml");
    std::fs::write(&redis, "[tile_cache]\nbackend = \"redis\"\nredis_url = \"redis://127.0.0.1:1/0\"\n").unwrap();
    let list = dir.join("list.txt");
    std::fs::write(&list, "dem/3/30/42\ncem/nine/1/1\n").unwrap();
    // A tile off the region: the server keeps nothing there, nor may a seed.
    let off = dir.join("off.txt");
    std::fs::write(&off, "dem/3/1/1\n").unwrap();
    // A cache directory that cannot be made (a file is in the way).
    let file = dir.join("a-file");
    std::fs::write(&file, "").unwrap();
    let cache = file.join("cache");
    // Regression: the path and the cause alone, not what failed.
    let unmakeable = format!("cannot create the cache directory {}: {} is a file", cache.display(), file.display());
    // A cache directory that is a link to nothing (was "File exists").
    let dangling = dir.join("dangling");
    std::os::unix::fs::symlink(dir.join("nowhere"), &dangling).unwrap();
    let link = format!("{} is a link to {}, which is no directory", dangling.display(), dir.join("nowhere").display());
    // A list names its layers and levels.
    let listed = ["--tiles-from", list.to_str().unwrap()];
    // Bad usage exits 2, bad files 1.
    let cases: [(&[&str], &str, i32); 15] = [
        (&["--levels", "12-3"], "--levels \"12-3\": FROM is above TO", 2),
        (
            &["--levels", "0-5", "--coverage", geojson.to_str().unwrap()],
            "points.geojson: Point geometries cannot be seeded",
            1,
        ),
        (&["--levels", "0-5", "--config", redis.to_str().unwrap()], "Redis at redis://127.0.0.1:1/0", 1),
        (&["--levels", "0-5", "--shard", "4/4"], "--shard \"4/4\"", 2),
        (&["--tiles-from", list.to_str().unwrap()], "list.txt:2", 1),
        (&["--tiles-from", off.to_str().unwrap()], "off.txt:1: tile 3/1/1 does not meet the region", 1),
        (&["--levels", "0-5", "--layers", "trees"], "unknown \"trees\"", 2),
        (&["--levels", "0-5", "--cache-dir", cache.to_str().unwrap()], &unmakeable, 1),
        (&["--grid", "tms"], "--grid: unknown \"tms\"; expected one of worldwind, xyz", 2),
        (&["--grid", "cesium", "--layers", "relief"], "expected some of dem, cem (in cesium tiles)", 2),
        (&["--grid", "xyz", "--formats", "png16"], "xyz tiles come in one format", 2),
        (&["--grid", "cesium", "--levels", "0-20"], "cesium cem tiles go down to level", 2),
        (&["--levels", "0-5", "--cache-dir", dangling.to_str().unwrap()], &link, 1),
        (&[&listed[..], &["--layers", "dem"]].concat(), "cannot be used with '--layers <LAYERS>'", 2),
        (
            &[&listed[..], &["--shard", "0/2", "--failed-file", list.to_str().unwrap()]].concat(),
            "give each shard its own --failed-file",
            2,
        ),
    ];
    for (args, needle, code) in cases {
        let out = seed(&dir.0, args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

#[test]
fn a_seeder_killed_mid_run_resumes_to_the_same_cache() {
    let dir = TempDir::new("seed-kill");
    let config = rmnp_config(&dir, "rmnp.toml", "[tile_cache]\nlock_ttl_s = 1");
    // Long enough (one worker, ~3,000 files) that the seeder is still busy
    // when it first saves its progress, after a second.
    let job = ["--config", config.to_str().unwrap(), "--layers", "dem", "--levels", "6-12", "--concurrency", "1"];
    let reference = dir.join("reference");
    ok(&seed(
        &dir.0,
        &[&job[..], &["--cache-dir", reference.to_str().unwrap(), "--progress-file", "ref.json"]].concat(),
    ));
    let expected = tiles(&reference);

    let cache = dir.join("cache");
    // Killed once it has saved its progress, well before the end.
    let job_here = [&job[..], &["--cache-dir", cache.to_str().unwrap()]].concat();
    let mut child = seed_until_progress(&dir.0, &job_here, Stdio::null());
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let partial = walk(&cache).len();
    assert!(partial < expected.len(), "killed after the end: {partial} files");

    // A dry run of the resumed job counts what it has left.
    let dry = |job: &[&str]| dry_total(&ok(&seed(&dir.0, &[job, &["--resume", "--dry-run"]].concat())));
    let (_, left) = dry(&job);
    let (_, all) = dry_total(&ok(&seed(&dir.0, &[&job[..], &["--dry-run"]].concat())));
    assert!(0 < left && left < all, "{left} of {all} files left");

    // Resumed into another cache, the finished subtrees would be missing there.
    let elsewhere = seed(&dir.0, &[&job[..], &["--cache-dir", "other", "--resume"]].concat());
    let err = String::from_utf8_lossy(&elsewhere.stderr);
    assert!(!elsewhere.status.success() && err.contains("this job wrote to the cache directory"), "{err}");
    let out = seed(&dir.0, &[&job[..], &["--cache-dir", cache.to_str().unwrap(), "--resume"]].concat());
    let summary = ok(&out);
    assert!(count(&summary, "tile files made") <= left, "{summary}");
    ends_at_its_total(&out);
    assert_eq!(dry(&job).1, 0, "nothing is left once the job is complete");
    let resumed = tiles(&cache);
    assert_eq!(resumed.keys().collect::<Vec<_>>(), expected.keys().collect::<Vec<_>>());
    assert!(resumed == expected, "the resumed cache differs from an uninterrupted run");
    let made = count(&summary, "tile files made");
    assert!(made < expected.len() as u64, "the resumed run remade everything: {summary}");
    let names = walk(&cache).into_iter().filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()));
    let temporaries: Vec<String> = names.filter(|n| n.starts_with('.') && n.ends_with(".tmp")).collect();
    assert!(temporaries.is_empty(), "the killed seeder's temporaries were left: {temporaries:?}");
}

/// Asserts that a seed's last progress line counts all its files, no more
/// (regression: a resumed run counted the files earlier runs made under an
/// unfinished subtree twice, and ended at 3349/3348).
fn ends_at_its_total(out: &Output) {
    let log = String::from_utf8_lossy(&out.stderr);
    let last = log.lines().rev().find_map(|l| l.strip_prefix("seed: ")).unwrap_or_else(|| panic!("{log}"));
    let (done, total) = last.split_once(' ').and_then(|(f, _)| f.split_once('/')).unwrap();
    assert_eq!(done, total, "{last}");
}

#[test]
fn ctrl_c_stops_a_seed_after_its_tiles_in_hand_with_no_lock_left() {
    let dir = TempDir::new("seed-ctrl-c");
    let config = rmnp_config(&dir, "rmnp.toml", "[tile_cache]\nlock_ttl_s = 30");
    let cache = dir.join("cache");
    let owned = job_args(&config, &cache, "dem", "6-12", &["--concurrency", "1"]);
    let job = strs(&owned);
    let child = seed_until_progress(&dir.0, &job, Stdio::piped());
    let interrupt = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(interrupt.success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.code() == Some(130) && err.contains("interrupted") && err.contains("--resume"), "{err}");
    let locks: Vec<_> = walk(&cache).into_iter().filter(|p| p.extension().is_some_and(|e| e == "lock")).collect();
    assert!(locks.is_empty(), "locks left: {locks:?}");
    // The progress was saved: a resumed run has less left than the job.
    let (_, left) = dry_total(&ok(&seed(&dir.0, &[&job[..], &["--resume", "--dry-run"]].concat())));
    let (_, all) = dry_total(&ok(&seed(&dir.0, &[&job[..], &["--dry-run"]].concat())));
    assert!(0 < left && left < all, "{left} of {all} files left");
    // Resumed at once: no lock of the interrupted run to wait for.
    let resumed = seed(&dir.0, &[&job[..], &["--resume"]].concat());
    ok(&resumed);
    assert!(!String::from_utf8_lossy(&resumed.stderr).contains("waiting for"));
}

#[test]
fn a_second_job_on_the_same_progress_file_is_refused_and_the_first_resumes() {
    // Regression: a second job started in the same directory overwrote the
    // first one's progress file (and emptied its failed-tiles file), so the
    // first, interrupted, could no longer resume.
    let dir = TempDir::new("seed-two-jobs");
    let config = rmnp_config(&dir, "rmnp.toml", "");
    let cache = dir.join("cache");
    let first_job = job_args(&config, &cache, "dem", "6-12", &["--concurrency", "1"]);
    let first = seed_until_progress(&dir.0, &strs(&first_job), Stdio::piped());
    let second = seed(&dir.0, &strs(&job_args(&config, &cache, "cem", "6-8", &[])));
    let err = String::from_utf8_lossy(&second.stderr);
    let named = ["seed-progress.json is in use", &format!("pid {}", first.id()), "--progress-file"];
    assert!(!second.status.success() && named.iter().all(|n| err.contains(n)), "{err}");
    let interrupt = Command::new("kill").args(["-INT", &first.id().to_string()]).status().unwrap();
    assert!(interrupt.success());
    let out = first.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", String::from_utf8_lossy(&out.stderr));
    ok(&seed(&dir.0, &[&strs(&first_job)[..], &["--resume"]].concat()));
    let names = std::fs::read_dir(&dir.0).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned());
    let locks: Vec<String> = names.filter(|n| n.ends_with(".lock")).collect();
    assert!(locks.is_empty(), "the jobs' lock files were left: {locks:?}");
}

#[test]
fn a_wait_for_a_lock_left_by_an_interrupted_seed_is_explained() {
    let dir = TempDir::new("seed-stale-lock");
    let config = rmnp_config(&dir, "rmnp.toml", "[tile_cache]\nlock_ttl_s = 6");
    let cache = dir.join("cache");
    let job = job_args(&config, &cache, "dem", "6-8", &[]);
    ok(&seed(&dir.0, &strs(&job)));
    // A tile gone, and the lock a killed seeder held on it left behind.
    let key = tiles(&cache).into_keys().next().unwrap();
    std::fs::remove_file(cache.join(&key)).unwrap();
    std::fs::write(cache.join(format!("{key}.lock")), "killed-seeder").unwrap();
    // Kept: a new job remakes tiles older than itself, which on a busy
    // machine the first job's may already be.
    let out = seed(&dir.0, &[&strs(&job)[..], &["--skip-existing"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("waiting for {key}")) && err.contains("lock_ttl_s"), "{err}");
    assert_eq!(err.matches("waiting for").count(), 1, "said once: {err}");
    assert_eq!(count(&ok(&out), "tile files made"), 1, "the tile is made once the lock expires");
}

/// A Terrarium upstream on loopback: sea (0 m) west of `SEA_EAST`, hills
/// east of it; the zoom-13 tile holding `(BAD_LON, BAD_LAT)` answers 500
/// until healed. Counts requests per path.
struct Upstream {
    base: String,
    healed: std::sync::Arc<std::sync::atomic::AtomicBool>,
    requests: std::sync::Arc<std::sync::Mutex<BTreeMap<String, u32>>>,
    bad: String,
}

const SEA_EAST: f64 = 10.04;
const BAD_LON: f64 = 10.07;
const BAD_LAT: f64 = 46.37;

impl Upstream {
    fn start() -> Upstream {
        use std::io::{Read, Write};
        use std::sync::atomic::Ordering;
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let base = format!("http://{}", listener.local_addr().unwrap());
        let n = f64::from(1u32 << 13);
        let (bx, by) = (
            ((BAD_LON + 180.0) / 360.0 * n) as u64,
            ((1.0 - BAD_LAT.to_radians().tan().asinh() / std::f64::consts::PI) / 2.0 * n) as u64,
        );
        let bad = format!("/13/{bx}/{by}.png");
        let up = Upstream { base, healed: Default::default(), requests: Default::default(), bad: bad.clone() };
        let (healed, requests) = (up.healed.clone(), up.requests.clone());
        std::thread::spawn(move || {
            for mut stream in listener.incoming().flatten() {
                let mut buf = [0u8; 2048];
                let n = stream.read(&mut buf).unwrap_or(0);
                let path = String::from_utf8_lossy(&buf[..n]).split_whitespace().nth(1).unwrap_or("").to_string();
                *requests.lock().unwrap().entry(path.clone()).or_default() += 1;
                let reply = match (path == bad && !healed.load(Ordering::SeqCst), terrarium_tile(&path)) {
                    (false, Some(png)) => [format!("HTTP/1.1 200 OK\r\nContent-Type: image/png\r\nContent-Length: {}\r\nConnection: close\r\n\r\n", png.len()).into_bytes(), png].concat(),
                    _ => b"HTTP/1.1 500 Internal Server Error\r\nContent-Length: 4\r\nConnection: close\r\n\r\nboom".to_vec(),
                };
                let _ = stream.write_all(&reply);
            }
        });
        up
    }
}

/// The Terrarium PNG of `/z/x/y.png`.
pub fn terrarium_tile(path: &str) -> Option<Vec<u8>> {
    let parts: Vec<u64> =
        path.trim_start_matches('/').trim_end_matches(".png").split('/').filter_map(|p| p.parse().ok()).collect();
    let [z, x, y] = parts[..] else { return None };
    let n = (256u64 << z) as f64;
    let heights = sylva::raster::Raster::from_fn(256, 256, |px, py| {
        let lon = ((x * 256 + px as u64) as f64 + 0.5) / n * 360.0 - 180.0;
        let lat =
            (std::f64::consts::PI * (1.0 - 2.0 * ((y * 256 + py as u64) as f64 + 0.5) / n)).sinh().atan().to_degrees();
        if lon < SEA_EAST { 0.0 } else { (1500.0 + 300.0 * (lon * 90.0).sin() * (lat * 70.0).cos()) as f32 }
    });
    sylva::encode::terrarium::encode(&heights).ok()
}

#[test]
fn failing_tiles_are_retried_listed_and_rerun_and_uniform_tiles_are_stored_once() {
    let dir = TempDir::new("seed-fail");
    let up = Upstream::start();
    let config = dir.join("up.toml");
    std::fs::write(&config, format!(
        "name = \"upstream\"\n[dem.upstream]\nservice = \"terrarium\"\nurl = \"{}/{{z}}/{{x}}/{{y}}.png\"\nzoom = 13\nbounds = [9.9, 46.2, 10.2, 46.5]\nretries = 0\nbreaker_failures = 1000000\n[tile_cache]\nlock_ttl_s = 2\n",
        up.base
    )).unwrap();
    let cache = dir.join("cache");
    let job = [
        "--config",
        config.to_str().unwrap(),
        "--cache-dir",
        cache.to_str().unwrap(),
        "--layers",
        "dem",
        "--levels",
        "9-10",
        "--bbox",
        "10.0,46.3,10.1,46.4",
        "--retries",
        "1",
        "--formats",
        "bil16,png16",
    ];
    // Too many failures stop the run.
    let stopped = seed(&dir.0, &[&job[..], &["--max-failures", "0"]].concat());
    assert_eq!(stopped.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&stopped.stderr).contains("more than --max-failures 0"),
        "{}",
        String::from_utf8_lossy(&stopped.stderr)
    );
    // Otherwise failed tiles are skipped and listed, with exit status 3.
    let out = seed(&dir.0, &job);
    assert_eq!(out.status.code(), Some(3), "{}", String::from_utf8_lossy(&out.stderr));
    let listed = std::fs::read_to_string(dir.join("seed-failed.txt")).unwrap();
    let failed: Vec<&str> = listed.lines().map(|l| l.split(' ').next().unwrap()).collect();
    assert!(!failed.is_empty() && listed.contains("HTTP 500"), "{listed}");
    assert!(listed.lines().all(|l| l.contains(" bil16,png16\t")), "each tile in both formats: {listed}");
    assert!(up.requests.lock().unwrap()[&up.bad] >= 2 * failed.len() as u32, "each failed tile was tried twice");
    let partial = tiles(&cache);
    for f in &failed {
        let p: Vec<&str> = f.split('/').collect();
        for ext in ["bil", "png"] {
            let key = format!("{}/{}/{}/{}_{}.{ext}", p[0], p[1], p[2], p[2], p[3]);
            assert!(!partial.keys().any(|k| k.ends_with(&key)), "{key} was stored");
        }
    }
    // Healed, a resumed run retries what failed, and only that (regression:
    // failed tiles were recorded as finished, the resumed run made nothing
    // and exited 0).
    let list = dir.join("failed-first.txt");
    std::fs::copy(dir.join("seed-failed.txt"), &list).unwrap();
    // A resumed dry run says that the tiles above the failures are counted
    // but will be found in the cache.
    let dry = ok(&seed(&dir.0, &[&job[..], &["--resume", "--dry-run"]].concat()));
    assert!(dry.contains(&format!("{} tile(s) failed earlier", failed.len())), "{dry}");
    up.healed.store(true, std::sync::atomic::Ordering::SeqCst);
    let out = seed(&dir.0, &[&job[..], &["--resume"]].concat());
    let resumed = ok(&out);
    ends_at_its_total(&out);
    assert_eq!(count(&resumed, "tile files made"), 2 * failed.len() as u64, "{resumed}");
    assert!(tiles(&cache).len() > partial.len());
    assert_eq!(std::fs::read_to_string(dir.join("seed-failed.txt")).unwrap(), "", "the healed tiles are not listed");
    // The first list is re-run: the cache is complete and equals one healthy run.
    let rerun = ok(&seed(
        &dir.0,
        &[
            "--config",
            config.to_str().unwrap(),
            "--cache-dir",
            cache.to_str().unwrap(),
            "--tiles-from",
            list.to_str().unwrap(),
        ],
    ));
    // In the formats listed, not the default --formats bil16 (those the
    // resumed run made a moment ago count as the job's own).
    let listed_files = count(&rerun, "tile files made") + count(&rerun, "already there");
    assert_eq!(listed_files, 2 * failed.len() as u64, "{rerun}");
    let healthy = dir.join("healthy");
    ok(&seed(
        &dir.0,
        &[&job[..2], &["--cache-dir", healthy.to_str().unwrap()], &job[4..], &["--progress-file", "h.json"]].concat(),
    ));
    let (repaired, expected) = (tiles(&cache), tiles(&healthy));
    assert!(repaired == expected, "the repaired cache differs from a healthy run");
    // The sea tiles are one stored file per format and links to it.
    let links: Vec<PathBuf> = walk(&cache)
        .into_iter()
        .filter(|p| {
            std::fs::symlink_metadata(p).unwrap().file_type().is_symlink() && p.extension().is_some_and(|e| e == "bil")
        })
        .collect();
    assert!(links.len() >= 4, "{} links", links.len());
    let targets: std::collections::BTreeSet<PathBuf> =
        links.iter().map(|l| std::fs::canonicalize(l).unwrap()).collect();
    assert_eq!(targets.len(), 1, "{targets:?}");
    let sea = &repaired[&links[0].strip_prefix(&cache).unwrap().to_string_lossy().into_owned()];
    assert!(sea.chunks_exact(2).all(|c| c == [0, 0]), "a sea tile is 0 m everywhere");
}

#[test]
fn existing_tiles_are_remade_or_kept_as_asked() {
    let dir = TempDir::new("seed-refresh");
    let config = rmnp_config(&dir, "rmnp.toml", "");
    let cache = dir.join("cache");
    let owned = job_args(&config, &cache, "dem", "6-7", &[]);
    let job = strs(&owned);
    let run = |extra: &[&str]| {
        // Entries up to 50 ms older than a job count as its own (coarse file times).
        std::thread::sleep(Duration::from_millis(100));
        let summary = ok(&seed(&dir.0, &[&job[..], extra].concat()));
        (count(&summary, "tile files made"), count(&summary, "already there"))
    };
    let (n, _) = run(&[]);
    assert!(n > 0);
    // By default a job remakes what was there before it started.
    assert_eq!(run(&[]), (n, 0));
    assert_eq!(run(&["--skip-existing"]), (0, n));
    assert_eq!(run(&["--refresh-before", "2000-01-01"]), (0, n));
    assert_eq!(run(&["--refresh-before", "2999-01-01T00:00:00Z"]), (n, 0));
}

#[test]
fn a_box_across_the_antimeridian_over_a_global_region_is_one_piece() {
    // Regression: over a region of every longitude, `--bbox=170,…,190,…`
    // was refused as meeting it "on both sides of the antimeridian".
    use sylva::grid::{Axis, SampleGrid};
    let dir = TempDir::new("seed-global");
    let grid = SampleGrid { lon: Axis::degrees(-179.5, 1.0, 0, 360), lat: Axis::degrees(89.5, -1.0, 0, 180) };
    let dem = sylva::raster::Raster::from_fn(360, 180, |x, y| (x + y) as f32);
    let tiff = sylva::encode::geotiff::write(sylva::encode::Samples::Float(&dem), &grid).unwrap();
    std::fs::write(dir.join("world.tif"), tiff).unwrap();
    std::fs::write(dir.join("world.toml"), "[dem]\npath = \"world.tif\"\n").unwrap();
    let config = dir.join("world.toml");
    let planned = |bbox: &str| {
        let args = ["--config", config.to_str().unwrap(), "--layers", "dem", "--levels", "4-6", "--dry-run"];
        dry_total(&ok(&seed(&dir.0, &[&args[..], &[&format!("--bbox={bbox}")]].concat()))).0
    };
    let (west, east) = (planned("170,-20,180,-10"), planned("-180,-20,-170,-10"));
    assert!(west > 0 && east > 0);
    assert_eq!(planned("170,-20,190,-10"), west + east);
}

/// A quadtree set's or Cesium's cache key (`version/xyz/relief/z/x/y.png`,
/// `…/crs84/…`, `…/cesium/cem/z/x/y.terrain`) → the server's product and
/// its URL path.
fn quad_product_of(key: &str) -> (Product, String) {
    use sylva::grid::quad::TileSet;
    let parts: Vec<&str> = key.split('/').collect();
    let [_, grid, layer, z, x, file] = parts[..] else { panic!("{key}") };
    let (y, ext) = file.split_once('.').unwrap();
    let zxy = (z.parse().unwrap(), x.parse().unwrap(), y.parse().unwrap());
    let map_layer = MapLayer::parse(layer).unwrap();
    match (grid, ext) {
        ("xyz", "png") => (
            Product::Quad { layer: map_layer, set: TileSet::WebMercator, zxy },
            format!("/xyz/{layer}/{z}/{x}/{y}.png"),
        ),
        ("crs84", "png") => (
            Product::Quad { layer: map_layer, set: TileSet::Crs84, zxy },
            format!("/wmts/1.0.0/{layer}/default/WorldCRS84Quad/{z}/{y}/{x}.png"),
        ),
        ("cesium", "terrain") => {
            let MapLayer::Data(layer) = map_layer else { panic!("{key}") };
            (Product::Terrain { layer, zxy }, format!("/cesium/{}/{z}/{x}/{y}.terrain", layer.name()))
        }
        _ => panic!("{key}"),
    }
}

#[test]
fn quadtree_and_cesium_tiles_are_seeded_as_the_server_serves_them() {
    use sylva::grid::quad::TileSet;
    let dir = TempDir::new("seed-quad");
    let cache = dir.join("cache");
    let at = ["--cache-dir", cache.to_str().unwrap()];
    let jobs: [&[&str]; 3] = [
        &["--grid", "xyz", "--layers", "relief,dem", "--levels", "10-12"],
        // The matrices WMTS advertises, by default.
        &["--grid", "WorldCRS84Quad", "--layers", "dem"],
        // Each layer to the deepest zoom its layer.json lists (cem's is deeper).
        &["--grid", "cesium", "--layers", "dem,cem", "--bbox", "10.1,46.35,10.12,46.37"],
    ];
    let mut planned = 0;
    for job in jobs {
        planned += dry_total(&ok(&seed(&dir.0, &[job, &["--dry-run"]].concat()))).1;
        ok(&seed(&dir.0, &[job, &at].concat()));
    }
    // The tiles, not the blob uniform ones share (zoom 0's and 1's samples
    // all miss the region: no data).
    let entries = |cache: &Path| -> BTreeMap<String, Vec<u8>> {
        tiles(cache).into_iter().filter(|(k, _)| !k.contains("/uniform/")).collect()
    };
    let seeded = entries(&cache);
    assert_eq!(seeded.len() as u64, planned);
    let region = sylva::config::load(None).unwrap();
    let zooms = |dir: &str| {
        let z = seeded.keys().filter(|k| k.contains(dir)).map(|k| k.split('/').nth(3).unwrap().parse().unwrap());
        z.clone().min().zip(z.max()).unwrap()
    };
    use sylva::cem::Layer::{Cem, Dem};
    // Every matrix WMTS lists, to the set's deepest (past dem's own).
    let deepest_matrix = sylva::server::wmts::deepest_matrix(&region, TileSet::Crs84).unwrap();
    assert_eq!(zooms("/crs84/"), (0, deepest_matrix));
    assert_eq!(zooms("/xyz/"), (10, 12));
    let deepest = |layer| sylva::server::cesium::deepest(&region, layer);
    assert!(deepest(Cem) > deepest(Dem));
    assert_eq!((zooms("/cesium/dem/"), zooms("/cesium/cem/")), ((0, deepest(Dem)), (0, deepest(Cem))));
    // Byte-identical to what the server computes on demand, and answered
    // from the cache at the tiles' URLs.
    let server = Server::start(None, &cache);
    for (key, bytes) in &seeded {
        let (product, path) = quad_product_of(key);
        assert!(products::compute(&region, &product).unwrap().bytes == *bytes, "{key} differs from the on-demand tile");
        let reply = server.get(&path);
        assert_eq!(reply.status, if bytes.is_empty() { 404 } else { 200 }, "{path}");
        assert!(reply.body == *bytes, "{path}");
    }
    assert_eq!(server.metric("sylva_tile_computations_total"), 0.0);
    assert_eq!(server.metric("sylva_tile_cache_total{result=\"hit\"}"), seeded.len() as f64);
    // A list of such tiles (as a failed-tiles file writes them) seeds the same bytes.
    let some: Vec<&String> = seeded.keys().step_by(7).collect();
    let lines: String =
        some.iter().map(|k| format!("{}\n", k.split_once('/').unwrap().1.split('.').next().unwrap())).collect();
    std::fs::write(dir.join("list.txt"), lines).unwrap();
    let again = dir.join("again");
    ok(&seed(&dir.0, &["--tiles-from", "list.txt", "--cache-dir", again.to_str().unwrap()]));
    let listed = entries(&again);
    assert_eq!(listed.len(), some.len());
    assert!(some.iter().all(|k| listed.get(*k) == seeded.get(*k)), "a listed tile differs from the walk's");
    // Its dry run counts it; its shards split it.
    let dry = ok(&seed(&dir.0, &["--tiles-from", "list.txt", "--dry-run"]));
    assert_eq!(dry_total(&dry).0, some.len() as u64, "{dry}");
    let shards: Vec<BTreeMap<String, Vec<u8>>> = (0..2)
        .map(|i| {
            let cache = dir.join(&format!("shard{i}"));
            let shard = format!("{i}/2");
            ok(&seed(&dir.0, &["--tiles-from", "list.txt", "--shard", &shard, "--cache-dir", cache.to_str().unwrap()]));
            entries(&cache)
        })
        .collect();
    assert_eq!(shards[0].len() + shards[1].len(), some.len(), "the shards overlap or leave tiles out");
    assert!(shards.iter().flatten().all(|(k, bytes)| listed.get(k) == Some(bytes)));
}
