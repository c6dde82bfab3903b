//! The server's commands: `serve` and `seed`.

use anyhow::Result;
use std::path::PathBuf;

/// `sylva serve`.
#[derive(clap::Args)]
pub struct ServeArgs {
    /// Region and server configuration (default: the embedded demo region).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Address to listen on, HOST:PORT (default: `[server] bind`).
    #[arg(long, value_parser = bind_address)]
    bind: Option<String>,
    /// Tile cache directory (default: `[tile_cache]`).
    #[arg(long)]
    cache_dir: Option<PathBuf>,
}

impl ServeArgs {
    /// Serves until SIGTERM.
    pub fn run(self) -> Result<()> {
        with_server_allocator();
        let options = sylva::server::ServeOptions { bind: self.bind, cache_dir: self.cache_dir };
        let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
        runtime.block_on(sylva::server::serve(self.config.as_deref(), options))
    }
}

/// `--bind`'s parser.
fn bind_address(text: &str) -> Result<String, String> {
    sylva::config::check_bind(text).map(|()| text.to_string())
}

/// `sylva seed`.
#[derive(clap::Args)]
pub struct SeedArgs {
    /// Region and tile cache configuration (default: the embedded demo region).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Tile cache directory (default: `[tile_cache]`).
    #[arg(long)]
    cache_dir: Option<PathBuf>,
    /// The tiles: worldwind (`/tiles`), xyz (WebMercatorQuad: `/xyz` and WMTS),
    /// crs84 (WorldCRS84Quad: WMTS) or cesium (`/cesium` terrain).
    #[arg(long, default_value = "worldwind", conflicts_with = "tiles_from")]
    grid: String,
    /// Layers, comma-separated: dem, cover, canopy, cem, surface, max4, max32;
    /// xyz and crs84 also colour and relief, not cover or surface; cesium dem and cem.
    #[arg(long, default_value = "cem", conflicts_with = "tiles_from")]
    layers: String,
    /// Formats of worldwind tiles, comma-separated: bil16 (.bil, the default),
    /// bil32, png16 (.png), tiff (.tif).
    #[arg(long)]
    formats: Option<String>,
    /// Levels, FROM-TO or one level (default for xyz, crs84 and cesium: the
    /// zooms the server advertises).
    #[arg(long)]
    levels: Option<String>,
    /// W,S,E,N in degrees (default: the region's bounds).
    #[arg(long, allow_hyphen_values = true, conflicts_with = "coverage")]
    bbox: Option<String>,
    /// GeoJSON Polygons or MultiPolygons (holes allowed) instead of a box.
    #[arg(long)]
    coverage: Option<PathBuf>,
    /// Seed the tiles listed in FILE (`layer/level/row/col [formats]` per line, a line's
    /// formats, e.g. `png16,tiff`, replacing --formats; or `xyz|crs84|cesium/layer/z/x/y`),
    /// e.g. a failed-tiles file.
    #[arg(long, conflicts_with_all = ["levels", "bbox", "coverage", "resume"])]
    tiles_from: Option<PathBuf>,
    /// Print the tiles per level and stop.
    #[arg(long)]
    dry_run: bool,
    /// Worker threads (0 = one per core).
    #[arg(long, default_value_t = 0)]
    concurrency: usize,
    /// Continue the job recorded in the progress file.
    #[arg(long)]
    resume: bool,
    /// Progress file (default: seed-progress.json, seed-progress-I-of-N.json with --shard).
    #[arg(long)]
    progress_file: Option<PathBuf>,
    /// Failed-tiles file (default: seed-failed.txt, seed-failed-I-of-N.txt with --shard).
    #[arg(long)]
    failed_file: Option<PathBuf>,
    /// Remake tiles written before DATE (2026-12-01 or 2026-12-01T12:00:00Z);
    /// default: before this job started.
    #[arg(long, conflicts_with = "skip_existing")]
    refresh_before: Option<String>,
    /// Keep every valid tile already in the cache.
    #[arg(long)]
    skip_existing: bool,
    /// Retries of a failing tile before it is listed as failed.
    #[arg(long, default_value_t = 2)]
    retries: u32,
    /// Stop (non-zero exit) after more than N failed tile files.
    #[arg(long, default_value_t = 1000)]
    max_failures: u64,
    /// Seed part I (0-based) of N disjoint parts (of a --tiles-from list:
    /// every N-th line from the I-th).
    #[arg(long)]
    shard: Option<String>,
    /// Compute every tile rather than building parents from their children.
    #[arg(long)]
    no_from_children: bool,
    /// Plain log lines instead of a progress bar, or nothing.
    #[arg(long, value_parser = ["auto", "plain", "quiet"], default_value = "auto")]
    progress: String,
}

impl SeedArgs {
    /// Runs a seed; a run with failed tiles exits with status 3, one stopped
    /// by a signal with 128 + its number.
    pub fn run(self) -> Result<()> {
        use sylva::seed::display::Mode;
        let display = match self.progress.as_str() {
            "plain" => Mode::Plain,
            "quiet" => Mode::Quiet,
            _ => Mode::Auto,
        };
        let options = sylva::seed::SeedOptions {
            config: self.config,
            cache_dir: self.cache_dir,
            grid: self.grid,
            layers: self.layers,
            formats: self.formats,
            levels: self.levels,
            bbox: self.bbox,
            coverage: self.coverage,
            tiles_from: self.tiles_from,
            dry_run: self.dry_run,
            concurrency: self.concurrency,
            resume: self.resume,
            progress_file: self.progress_file,
            failed_file: self.failed_file,
            refresh_before: self.refresh_before,
            skip_existing: self.skip_existing,
            retries: self.retries,
            max_failures: self.max_failures,
            shard: self.shard,
            from_children: !self.no_from_children,
            display,
        };
        let report = match sylva::seed::run(&options, &sylva::seed::Counters::default()) {
            // Stopped by a signal: the status a shell gives a death by it.
            Err(e @ sylva::seed::SeedError::Interrupted { signal, .. }) => {
                sylva::outputs::say(format_args!("sylva: {e}"));
                std::process::exit(128 + signal)
            }
            Err(sylva::seed::SeedError::Usage(why)) => return Err(super::usage(why)),
            report => report?,
        };
        super::print(report.text)?;
        if report.failed > 0 {
            std::process::exit(3);
        }
        Ok(())
    }
}

/// mimalloc's setting for a long-running server: freed memory goes back to
/// the kernel after 50 ms instead of 1 s. Under `sylva bench soak` (10 min)
/// the peak resident memory was 489 MiB instead of 528 MiB, with as many
/// requests served. mimalloc reads its options from the environment when the
/// process starts, so the process re-executes itself once with the variable
/// set (same pid; a variable the caller set is kept). If that fails, the
/// server runs with the defaults.
pub fn with_server_allocator() {
    use std::os::unix::process::CommandExt;
    const VAR: &str = "MIMALLOC_PURGE_DELAY";
    if std::env::var_os(VAR).is_some() {
        return;
    }
    let Ok(exe) = std::env::current_exe() else { return };
    let error = std::process::Command::new(exe).args(std::env::args_os().skip(1)).env(VAR, "50").exec();
    sylva::outputs::say(format_args!("sylva: running with the allocator's defaults ({VAR} not applied: {error})"));
}
