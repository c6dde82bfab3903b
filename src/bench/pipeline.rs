//! `sylva bench pipeline`: per-stage time of one 513² tile with a 32-sample
//! halo on one thread (cold: fresh caches; warm: source blocks cached, as in a
//! running server), and the time of a 4096² whole-area CEM build on all cores.
//!
//! The tile computes what the dissertation's preprocessing produces: the CEM
//! and its 32-sample safety zone, then encodes the CEM as PNG16 (the same
//! steps as `shared/peers/baseline_pipeline.py`).

use super::{median_ms, table};
use crate::cem::{self, Layer, Stage};
use crate::encode::{self, Format, Samples};
use crate::grid::TileId;
use crate::region::Region;
use std::time::{Duration, Instant};

/// Samples of the tile benchmark (warm runs).
const RUNS: usize = 21;

/// Results for one region.
pub struct PipelineResult {
    /// Region name.
    pub region: String,
    /// The tile measured.
    pub tile: TileId,
    /// Median ms per stage (cold, warm), in [`Stage::ALL`] order, then encode.
    pub stages: Vec<(String, f64, f64)>,
    /// Median total ms (cold, warm).
    pub total: (f64, f64),
    /// Seconds for the whole-area build on all cores: (cold, warm).
    pub build_s: (f64, f64),
}

/// The tile nearest the region's centre on the level whose spacing is just
/// finer than the DEM's pixels (where a real client would look).
pub fn bench_tile(region: &Region) -> TileId {
    let b = region.bounds;
    let pixel = region.dem.georef().pixel_deg();
    let level =
        (0..=crate::grid::TileGrid::MAX_LEVEL).find(|&l| region.tiles.spacing_deg(l) <= pixel / 2.0).unwrap_or(12);
    region.tiles.tile_containing(0.5 * (b.west + b.east), 0.5 * (b.south + b.north), level)
}

/// Runs the benchmark on `region`; `reload` makes a fresh copy of the region
/// (empty caches) for the cold runs.
pub fn run(region: &Region, reload: &(dyn Fn() -> Region + Sync), build_side: usize) -> PipelineResult {
    let tile = bench_tile(region);
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build();
    let measure = |r: &Region| -> (Vec<Duration>, Duration) {
        let grid = r.tiles.tile_samples(tile, 32);
        let p = cem::compute(r, &grid, &[Layer::Cem, Layer::Max32]).unwrap_or_default();
        let start = Instant::now();
        if let Some(cem) = &p.cem {
            let _ = encode::encode(Layer::Cem, Samples::Float(cem), &grid, Format::Png16, r.heights_16);
        }
        let stages = Stage::ALL.iter().map(|&s| p.stats.elapsed(s)).collect();
        (stages, start.elapsed())
    };
    let sample = || {
        let cold: Vec<_> = (0..5).map(|_| measure(&reload())).collect();
        measure(region);
        let warm: Vec<_> = (0..RUNS).map(|_| measure(region)).collect();
        (cold, warm)
    };
    let (cold, warm) = match &one_thread {
        Ok(pool) => pool.install(sample),
        Err(_) => sample(),
    };
    let column = |runs: &[(Vec<Duration>, Duration)], i: usize| -> f64 {
        let mut v: Vec<Duration> = runs.iter().map(|(s, e)| if i < s.len() { s[i] } else { *e }).collect();
        median_ms(&mut v)
    };
    let total = |runs: &[(Vec<Duration>, Duration)]| {
        let mut v: Vec<Duration> = runs.iter().map(|(s, e)| s.iter().sum::<Duration>() + *e).collect();
        median_ms(&mut v)
    };
    let names = Stage::ALL.iter().map(|s| s.name().to_string()).chain(["encode png16".to_string()]);
    let stages = names.enumerate().map(|(i, n)| (n, column(&cold, i), column(&warm, i))).collect();
    let build = |r: &Region| {
        let start = Instant::now();
        let built = crate::produce::area(r, r.bounds, build_side, build_side, Layer::Cem, Format::Bil32);
        if built.is_ok() { start.elapsed().as_secs_f64() } else { f64::NAN }
    };
    let fresh = reload();
    let build_s = (build(&fresh), build(&fresh));
    PipelineResult { region: region.name.clone(), tile, stages, total: (total(&cold), total(&warm)), build_s }
}

/// The table of one result; `key` names the region in the summary line.
pub fn report(r: &PipelineResult, key: &str, build_side: usize) -> String {
    let mut rows: Vec<Vec<String>> =
        r.stages.iter().map(|(n, c, w)| vec![n.clone(), format!("{c:.2}"), format!("{w:.2}")]).collect();
    rows.push(vec!["total".into(), format!("{:.2}", r.total.0), format!("{:.2}", r.total.1)]);
    format!(
        "{} — tile {} (513² + 32-sample halo, cem + max32 + png16), one thread, median ms\n{}\n\n\
         build {build_side}² cem (bil32) on {} threads: {:.2} s cold, {:.2} s warm\n\
         summary region={key} warm_ms={:.2} cold_ms={:.2} build_cold_s={:.2} build_warm_s={:.2}\n",
        r.region,
        r.tile,
        table(&["stage", "cold", "warm"], &rows),
        rayon::current_num_threads(),
        r.build_s.0,
        r.build_s.1,
        r.total.1,
        r.total.0,
        r.build_s.0,
        r.build_s.1
    )
}
