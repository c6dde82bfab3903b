//! `sylva bench seed`: seeding speed and memory. Tiles per second seeding a
//! region's `cem` tiles on 1 and 2 workers, with and without building parents
//! from their children (and the same for `dem`, where more levels qualify),
//! then the other pyramids' tiles at the levels the server advertises (XYZ
//! `relief` and `dem`, WMTS CRS84 `relief`, Cesium `cem`) on the embedded
//! demo region (whose finer data the server advertises to deeper zooms than
//! rmnp's 234 m DEM: 213 XYZ tiles against 17), each into a fresh directory
//! cache; MapProxy's `mapproxy-seed` rate
//! (measured by `benches/seed.sh` in the same sitting) gives the ratio.
//! The machine is shared: every configuration runs twice, alternating, and
//! the faster run counts; the process's CPU time per file (user + system,
//! from `/proc/self/stat`) is given beside, as it does not depend on what
//! else the machine runs.
//!
//! Memory: resident memory in one process through a real seed of the
//! region's `cem` tiles, then a real ~155,000-tile job: the demo's XYZ `dem`
//! tiles to zoom 19 (a walk stays within its region's bounds, and rmnp's
//! World Wind tiles that many would be 80 GB).

use super::rss_mib;
use super::table;
use crate::seed::display::Mode;
use crate::seed::{Counters, SeedOptions};
use anyhow::{Result, anyhow};
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// What `sylva bench seed` runs.
#[derive(Clone, Debug)]
pub struct SeedBench {
    /// The region (the MapProxy peer seeds the same DEM).
    pub config: PathBuf,
    /// Levels of the speed runs.
    pub levels: String,
    /// Tile files per second of `mapproxy-seed` in this sitting, if measured.
    pub mapproxy_rate: Option<f64>,
    /// Zooms of the memory run's XYZ `dem` tiles of the demo region.
    pub memory_levels: String,
}

/// One speed run's job: the pyramid, a layer, World Wind's format (none
/// for the others), workers, and whether parents are built from children.
struct Run {
    grid: &'static str,
    layer: &'static str,
    format: Option<&'static str>,
    workers: usize,
    from_children: bool,
}

impl Run {
    const fn world_wind(layer: &'static str, format: &'static str, workers: usize, from_children: bool) -> Run {
        Run { grid: "worldwind", layer, format: Some(format), workers, from_children }
    }

    /// A quadtree or Cesium job on the demo region, 2 workers, at the
    /// advertised levels.
    const fn other(grid: &'static str, layer: &'static str) -> Run {
        Run { grid, layer, format: None, workers: 2, from_children: false }
    }

    fn label(&self) -> String {
        let workers = format!("{} worker{}", self.workers, if self.workers > 1 { "s" } else { "" });
        match self.format {
            Some(format) => {
                let parents = if self.from_children { "from children" } else { "computed" };
                format!("{} {format}, {workers}, parents {parents}", self.layer)
            }
            None => format!("{} {} (demo), {workers}, advertised levels", self.grid, self.layer),
        }
    }

    /// Its options into `dir`: World Wind's on the bench's region at its
    /// levels, the others on the demo at the levels the server advertises.
    fn options(&self, b: &SeedBench, dir: &Path) -> SeedOptions {
        let world_wind = self.grid == "worldwind";
        let base = options(b, dir, &b.levels);
        SeedOptions {
            config: base.config.clone().filter(|_| world_wind),
            grid: self.grid.into(),
            layers: self.layer.into(),
            formats: self.format.map(String::from),
            levels: base.levels.clone().filter(|_| world_wind),
            concurrency: self.workers,
            from_children: self.from_children,
            ..base
        }
    }
}

/// The speed runs; [`ratios`] reads the first six by position.
const RUNS: [Run; 10] = [
    Run::world_wind("cem", "bil16", 1, true),
    Run::world_wind("cem", "bil16", 2, true),
    Run::world_wind("cem", "bil16", 2, false),
    Run::world_wind("cem", "png16", 2, true),
    Run::world_wind("dem", "bil16", 2, true),
    Run::world_wind("dem", "bil16", 2, false),
    Run::other("xyz", "relief"),
    Run::other("xyz", "dem"),
    Run::other("crs84", "relief"),
    Run::other("cesium", "cem"),
];

/// One speed run.
struct Speed {
    label: String,
    files: u64,
    computed: u64,
    derived: u64,
    seconds: f64,
    cpu_seconds: f64,
}

impl Speed {
    fn rate(&self) -> f64 {
        self.files as f64 / self.seconds.max(1e-9)
    }
}

/// Runs the benchmark and returns its tables.
pub fn report(b: &SeedBench) -> Result<String> {
    let work = std::env::temp_dir().join(format!("sylva-bench-seed-{}", std::process::id()));
    let mut speeds: Vec<Option<Speed>> = RUNS.iter().map(|_| None).collect();
    let load_before = load_average();
    for round in 0..2 {
        for (i, run) in RUNS.iter().enumerate() {
            let dir = work.join(format!("run{i}-{round}"));
            let cpu = cpu_seconds();
            let (counters, seconds) = timed(&run.options(b, &dir))?;
            let cpu_seconds = cpu_seconds() - cpu;
            let _ = std::fs::remove_dir_all(&dir);
            let get = |c: &std::sync::atomic::AtomicU64| c.load(Ordering::Relaxed);
            let speed = Speed {
                label: run.label(),
                files: counters.total(),
                computed: get(&counters.computed),
                derived: get(&counters.derived),
                seconds,
                cpu_seconds,
            };
            if speeds[i].as_ref().is_none_or(|s| s.seconds > speed.seconds) {
                speeds[i] = Some(speed);
            }
        }
    }
    let speeds: Vec<Speed> = speeds.into_iter().flatten().collect();
    let mut out = vec![
        speed_table(b, &speeds),
        format!("load average (1 min) before and after the speed runs: {load_before} / {}", load_average()),
    ];
    out.extend(ratios(b, &speeds));
    out.push(memory(b, &work.join("memory"))?);
    let _ = std::fs::remove_dir_all(&work);
    Ok(out.join("\n"))
}

/// Seed options into `dir` (cache, progress and failed files), quiet.
fn options(b: &SeedBench, dir: &Path, levels: &str) -> SeedOptions {
    SeedOptions {
        config: Some(b.config.clone()),
        cache_dir: Some(dir.join("cache")),
        levels: Some(levels.into()),
        progress_file: Some(dir.join("progress.json")),
        failed_file: Some(dir.join("failed.txt")),
        display: Mode::Quiet,
        ..SeedOptions::default()
    }
}

/// Runs a seed and times it.
fn timed(options: &SeedOptions) -> Result<(Counters, f64)> {
    if let Some(dir) = options.progress_file.as_ref().and_then(|p| p.parent()) {
        std::fs::create_dir_all(dir)?;
    }
    let counters = Counters::default();
    let start = Instant::now();
    let report = crate::seed::run(options, &counters)?;
    if report.failed > 0 {
        return Err(anyhow!("{} tile files failed: {}", report.failed, report.text));
    }
    Ok((counters, start.elapsed().as_secs_f64()))
}

fn speed_table(b: &SeedBench, speeds: &[Speed]) -> String {
    let rows: Vec<Vec<String>> = speeds
        .iter()
        .map(|s| {
            vec![
                s.label.clone(),
                s.files.to_string(),
                s.computed.to_string(),
                s.derived.to_string(),
                format!("{:.1}", s.seconds),
                format!("{:.1}", s.rate()),
                format!("{:.2}", 1e3 * s.cpu_seconds / s.files.max(1) as f64),
            ]
        })
        .collect();
    format!(
        "sylva bench seed — {}, World Wind levels {}, fresh directory cache per run, faster of two alternated runs\n{}",
        b.config.display(),
        b.levels,
        table(&["run", "files", "computed", "from children", "s", "files/s", "CPU ms/file"], &rows)
    )
}

/// The saving of building parents from children, and the ratio to MapProxy.
fn ratios(b: &SeedBench, s: &[Speed]) -> Vec<String> {
    let saving = |with: &Speed, without: &Speed| {
        format!(
            "parents from children, {}: {} of {} files derived; CPU {:.1} s against {:.1} s computing every tile ({:.0} % less)",
            with.label.split(',').next().unwrap_or(""),
            with.derived,
            with.files,
            with.cpu_seconds,
            without.cpu_seconds,
            100.0 * (1.0 - with.cpu_seconds / without.cpu_seconds.max(1e-9)),
        )
    };
    let mut out = vec![saving(&s[1], &s[2]), saving(&s[4], &s[5])];
    out.push(format!("workers: 2 / 1 = {:.2}× files/s (cem bil16)", s[1].rate() / s[0].rate().max(1e-9)));
    if let Some(peer) = b.mapproxy_rate {
        out.push(format!("mapproxy-seed (dem png16 512², 2 processes): {peer:.1} tiles/s"));
        for i in [1, 3] {
            out.push(format!("ratio ({} / mapproxy-seed): {:.2}×", s[i].label, s[i].rate() / peer));
        }
    }
    let cpu_ms = 1e3 * s[1].cpu_seconds / s[1].files.max(1) as f64;
    out.push(format!(
        "cem bil16, 2 workers: {cpu_ms:.2} CPU ms per file, so at most {:.0} files/s on 2 idle cores",
        2e3 / cpu_ms
    ));
    out.push(format!("summary cem2_files_per_s={:.1} cem1_files_per_s={:.1}", s[1].rate(), s[0].rate()));
    out
}

/// Resident memory through a real seed of the region's `cem` tiles, then
/// the demo's XYZ `dem` tiles at the memory levels, in one process.
fn memory(b: &SeedBench, dir: &Path) -> Result<String> {
    let real = SeedOptions { concurrency: 2, ..options(b, dir, &b.levels) };
    let many = SeedOptions {
        config: None,
        grid: "xyz".into(),
        layers: "dem".into(),
        concurrency: 2,
        progress_file: Some(dir.join("many-progress.json")),
        ..options(b, dir, &b.memory_levels)
    };
    std::fs::create_dir_all(dir)?;
    let counters = Counters::default();
    let marks = [1_000u64, 2_000, 3_000, 5_000, 10_000, 20_000, 50_000, 100_000, 150_000];
    let mut rows = Vec::new();
    let row = |c: &Counters, start: Instant| {
        let (rss, peak) = rss_mib();
        let get = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed).to_string();
        vec![
            c.total().to_string(),
            get(&c.computed),
            format!("{rss:.0}"),
            format!("{peak:.0}"),
            format!("{:.0}", start.elapsed().as_secs_f64()),
        ]
    };
    let start = Instant::now();
    let texts = std::thread::scope(|scope| {
        let job = scope.spawn(|| -> Result<Vec<String>> {
            Ok(vec![crate::seed::run(&real, &counters)?.text, crate::seed::run(&many, &counters)?.text])
        });
        let mut next = 0;
        while !job.is_finished() {
            while next < marks.len() && counters.total() >= marks[next] {
                rows.push(row(&counters, start));
                next += 1;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        job.join().map_err(|_| anyhow!("the seed panicked"))
    })??;
    rows.push(row(&counters, start));
    let _ = std::fs::remove_dir_all(dir);
    Ok(format!(
        "\nmemory, one process, 2 workers: a real seed of levels {} (cem bil16), then the demo's XYZ dem tiles at zooms {}\n{}\n{}",
        b.levels,
        b.memory_levels,
        table(&["files done", "computed", "rss MiB", "peak MiB", "s"], &rows),
        texts.join("\n")
    ))
}

/// This process's CPU time (user + system), seconds.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which may hold spaces): utime is the 12th, stime the 13th.
    let after = stat.rsplit_once(')').map_or("", |(_, rest)| rest);
    let fields: Vec<&str> = after.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i).and_then(|f| f.parse::<f64>().ok());
    // Clock ticks are 100 per second on Linux (USER_HZ).
    ticks(11).zip(ticks(12)).map_or(f64::NAN, |(u, s)| (u + s) / 100.0)
}

/// The 1-minute load average.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next().map(String::from))
        .unwrap_or_default()
}
