//! `sylva bench seed`: seeding speed and memory. Tiles per second seeding a
//! region's `cem` tiles on 1 and 2 workers, with and without building parents
//! from their children (and the same for `dem`, where more levels qualify),
//! each into a fresh directory cache; MapProxy's `mapproxy-seed` rate
//! (measured by `benches/seed.sh` in the same sitting) gives the ratio.
//! Memory: resident memory while one job walks ~100,000 tiles, the first
//! thousands over the region's data (real `cem` tiles), the rest beyond it
//! (tiles without data, each still claimed, stored and linked).

use super::serve::rss_mib;
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
    /// Levels of the memory run (over a box 2.6° square from the region's
    /// south-west corner).
    pub memory_levels: String,
}

/// One speed run.
struct Speed {
    label: String,
    files: u64,
    computed: u64,
    derived: u64,
    seconds: f64,
}

impl Speed {
    fn rate(&self) -> f64 {
        self.files as f64 / self.seconds.max(1e-9)
    }
}

/// Runs the benchmark and returns its tables.
pub fn report(b: &SeedBench) -> Result<String> {
    let work = std::env::temp_dir().join(format!("sylva-bench-seed-{}", std::process::id()));
    let runs = [
        ("cem", "bil16", 1, true),
        ("cem", "bil16", 2, true),
        ("cem", "bil16", 2, false),
        ("cem", "png16", 2, true),
        ("dem", "bil16", 2, true),
        ("dem", "bil16", 2, false),
    ];
    let mut speeds = Vec::new();
    for (i, &(layer, format, workers, from_children)) in runs.iter().enumerate() {
        let dir = work.join(format!("run{i}"));
        let options = SeedOptions {
            layers: layer.into(),
            formats: format.into(),
            concurrency: workers,
            from_children,
            ..options(b, &dir, &b.levels, None)
        };
        let (counters, seconds) = timed(&options)?;
        let _ = std::fs::remove_dir_all(&dir);
        let label = format!(
            "{layer} {format}, {workers} worker{}, parents {}",
            if workers > 1 { "s" } else { "" },
            if from_children { "from children" } else { "computed" }
        );
        let get = |c: &std::sync::atomic::AtomicU64| c.load(Ordering::Relaxed);
        speeds.push(Speed {
            label,
            files: counters.total(),
            computed: get(&counters.computed),
            derived: get(&counters.derived),
            seconds,
        });
    }
    let mut out = vec![speed_table(b, &speeds)];
    out.extend(ratios(b, &speeds));
    out.push(memory(b, &work.join("memory"))?);
    let _ = std::fs::remove_dir_all(&work);
    Ok(out.join("\n"))
}

/// Seed options into `dir` (cache, progress and failed files), quiet.
fn options(b: &SeedBench, dir: &Path, levels: &str, bbox: Option<String>) -> SeedOptions {
    SeedOptions {
        config: Some(b.config.clone()),
        cache_dir: Some(dir.join("cache")),
        levels: Some(levels.into()),
        bbox,
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
            ]
        })
        .collect();
    format!(
        "sylva bench seed — {}, levels {}, fresh directory cache per run\n{}",
        b.config.display(),
        b.levels,
        table(&["run", "files", "computed", "from children", "s", "files/s"], &rows)
    )
}

/// The saving of building parents from children, and the ratio to MapProxy.
fn ratios(b: &SeedBench, s: &[Speed]) -> Vec<String> {
    let saving = |with: &Speed, without: &Speed| {
        format!(
            "parents from children, {}: {:.1} s against {:.1} s computing every tile ({:.0} % less time, {} of {} files derived)",
            with.label.split(',').next().unwrap_or(""),
            with.seconds,
            without.seconds,
            100.0 * (1.0 - with.seconds / without.seconds.max(1e-9)),
            with.derived,
            with.files
        )
    };
    let mut out = vec![saving(&s[1], &s[2]), saving(&s[4], &s[5])];
    out.push(format!("workers: 2 / 1 = {:.2}× (cem bil16)", s[1].rate() / s[0].rate().max(1e-9)));
    if let Some(peer) = b.mapproxy_rate {
        out.push(format!("mapproxy-seed (dem png16 512², 2 processes): {peer:.1} tiles/s"));
        for i in [1, 3] {
            out.push(format!("ratio ({} / mapproxy-seed): {:.2}×", s[i].label, s[i].rate() / peer));
        }
    }
    out.push(format!("summary cem2_files_per_s={:.1} cem1_files_per_s={:.1}", s[1].rate(), s[0].rate()));
    out
}

/// Resident memory while a ~100,000-tile job runs.
fn memory(b: &SeedBench, dir: &Path) -> Result<String> {
    let region = crate::config::load(Some(&b.config))?;
    let (w, s) = (region.bounds.west, region.bounds.south);
    let bbox = format!("{w},{s},{},{}", w + 2.6, s + 2.6);
    let options = SeedOptions { concurrency: 2, ..options(b, dir, &b.memory_levels, Some(bbox.clone())) };
    std::fs::create_dir_all(dir)?;
    let counters = Counters::default();
    let marks = [1_000u64, 2_000, 5_000, 10_000, 20_000, 50_000, 100_000];
    let mut rows = Vec::new();
    let start = Instant::now();
    let result = std::thread::scope(|scope| {
        let job = scope.spawn(|| crate::seed::run(&options, &counters));
        let mut next = 0;
        while !job.is_finished() {
            let done = counters.total();
            while next < marks.len() && done >= marks[next] {
                let (rss, peak) = rss_mib();
                let real = counters.computed.load(Ordering::Relaxed);
                rows.push(vec![
                    done.to_string(),
                    real.to_string(),
                    format!("{rss:.0}"),
                    format!("{peak:.0}"),
                    format!("{:.0}", start.elapsed().as_secs_f64()),
                ]);
                next += 1;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        job.join().map_err(|_| anyhow!("the seed panicked"))
    })??;
    let (rss, peak) = rss_mib();
    rows.push(vec![
        counters.total().to_string(),
        counters.computed.load(Ordering::Relaxed).to_string(),
        format!("{rss:.0}"),
        format!("{peak:.0}"),
        format!("{:.0}", start.elapsed().as_secs_f64()),
    ]);
    let _ = std::fs::remove_dir_all(dir);
    Ok(format!(
        "\nmemory: cem bil16, levels {}, bbox {bbox} (the region's data in its south-west corner), 2 workers\n{}\n{}",
        b.memory_levels,
        table(&["files done", "computed", "rss MiB", "peak MiB", "s"], &rows),
        result.text
    ))
}
