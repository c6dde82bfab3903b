//! The `sylva` command line: parses arguments, calls the library, writes
//! files, and maps errors to messages and exit codes (1: bad input or data,
//! 2: bad usage, from clap; 3: a seed finished with failed tiles).

#[cfg(feature = "client")]
use anyhow::Context;
use anyhow::{Result, bail};

/// Tiles allocate and free megabyte rasters at a high rate; glibc returns
/// them to the kernel each time and pays a page fault per 4 KiB on reuse
/// (22 % of a warm tile's time, measured with perf). mimalloc keeps them.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};
use sylva::cem::Layer;
#[cfg(feature = "client")]
use sylva::client::render::RayPass;
use sylva::encode::Format;
use sylva::grid::{BBox, TileId};
use sylva::outputs;
use sylva::produce::{self, Product};

#[derive(Parser)]
#[command(
    name = "sylva",
    version,
    about = "Combined elevation maps (terrain + forest canopy): tiles, builds and benchmarks"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Compute one World Wind tile.
    Tile {
        /// Region configuration (default: the embedded demo region).
        #[arg(long)]
        config: Option<PathBuf>,
        /// dem, cover, canopy, cem, surface, max4 or max32.
        #[arg(long)]
        layer: String,
        /// Tile level (0 = coarsest).
        #[arg(long)]
        level: u32,
        /// Tile row, counted from the south pole.
        #[arg(long)]
        row: u64,
        /// Tile column, counted from −180°.
        #[arg(long)]
        col: u64,
        /// Extra samples per side taken from the neighbours.
        #[arg(long, default_value_t = 0)]
        halo: usize,
        /// bil16, bil32, png16 or tiff.
        #[arg(long, default_value = "tiff")]
        format: String,
        /// Output file.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Compute a layer over a whole box in one go (the reference tiles match).
    Build {
        /// Region configuration (default: the embedded demo region).
        #[arg(long)]
        config: Option<PathBuf>,
        /// dem, cover, canopy, cem, surface, max4 or max32.
        #[arg(long)]
        layer: String,
        /// W,S,E,N in degrees (default: the region's bounds).
        #[arg(long, allow_hyphen_values = true)]
        bbox: Option<String>,
        /// Samples per row; the outer samples lie on the box edges.
        #[arg(long)]
        width: usize,
        /// Samples per column.
        #[arg(long)]
        height: usize,
        /// bil16, bil32, png16 or tiff.
        #[arg(long, default_value = "tiff")]
        format: String,
        /// Output file.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Serve WMS, World Wind and XYZ tiles over HTTP.
    #[cfg(feature = "server")]
    Serve {
        /// Region and server configuration (default: the embedded demo region).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Address to listen on (default: `[server] bind`).
        #[arg(long)]
        bind: Option<String>,
        /// Tile cache directory (default: `[tile_cache]`).
        #[arg(long)]
        cache_dir: Option<PathBuf>,
    },
    /// Fly a camera path headless: PNG frames and per-frame statistics.
    #[cfg(feature = "client")]
    Fly {
        #[command(flatten)]
        tiles: TileArgs,
        /// Camera path (TOML; see config/paths/).
        #[arg(long)]
        path: PathBuf,
        /// Frames spread evenly over the path (at least 1).
        #[arg(long, default_value_t = 60, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
        frames: usize,
        /// Output directory for frame_NNNNN.png and stats.csv.
        #[arg(long)]
        out: PathBuf,
        /// Replace an earlier flight's outputs in --out (else refused).
        #[arg(long)]
        overwrite: bool,
        /// Statistics only, no PNG frames.
        #[arg(long)]
        no_frames: bool,
        /// Render each frame again for this long and report its median
        /// GPU time: what a loop rendering continuously sees, where a GPU
        /// lowers its clocks between a CPU-bound flight's frames (an H200
        /// runs 5.7× slower then).
        #[arg(long, default_value_t = 0.0)]
        hold_ms: f64,
        #[command(flatten)]
        render: RenderArgs,
    },
    /// Fly over the tiles in a window, with keyboard and mouse (W/S/A/D
    /// move, Q/E down and up, arrows and a left drag look, Shift and the
    /// wheel set the speed, L sun, T traversal, P saves the frame, Esc quits).
    #[cfg(feature = "window")]
    View {
        #[command(flatten)]
        tiles: TileArgs,
        /// Start at this camera path's first keyframe, with its sun and
        /// field of view (default: above the middle of the region).
        #[arg(long)]
        path: Option<PathBuf>,
        /// Close after this many frames.
        #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
        frames: Option<usize>,
        /// Directory for stats.csv on closing (with the last frame when
        /// --frames is given) and for frames saved with P (default: here).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Replace an earlier flight's or view's outputs in --out (else
        /// refused).
        #[arg(long)]
        overwrite: bool,
        #[command(flatten)]
        render: RenderArgs,
    },
    /// Pregenerate tiles into the tile cache (resumable, parallel, sharded).
    #[cfg(feature = "server")]
    Seed(Box<SeedArgs>),
    /// Print benchmark tables.
    Bench {
        #[command(subcommand)]
        what: Bench,
    },
    /// Build a canopy proxy (Wang tiles) from LiDAR point clouds.
    Canopy {
        /// LAS or LAZ files, read as one cloud (repeat for more).
        #[arg(long = "las", required = true)]
        las: Vec<PathBuf>,
        /// Cell side of the canopy height model, metres.
        #[arg(long, default_value_t = 0.5)]
        resolution: f64,
        /// The proxy (a GeoTIFF atlas of Wang tiles).
        #[arg(short, long)]
        output: PathBuf,
        /// Also write the canopy height model (GeoTIFF).
        #[arg(long)]
        chm: Option<PathBuf>,
        /// Also write a picture of the CHM beside 3 × 3 tiles of the proxy (PNG).
        #[arg(long)]
        preview: Option<PathBuf>,
        /// `EPSG:code` replacing the files' CRS.
        #[arg(long)]
        crs: Option<String>,
        /// Tile side in texels, a power of two (default: about 64 m).
        #[arg(long)]
        tile_px: Option<usize>,
        /// Colours per tile edge (1: one periodic tile).
        #[arg(long, default_value_t = 2)]
        colours: usize,
        /// Tiles per colour combination.
        #[arg(long, default_value_t = 2)]
        variants: usize,
    },
    /// Describe the region a configuration makes.
    Info {
        /// Region configuration (default: the embedded demo region).
        #[arg(long)]
        config: Option<PathBuf>,
    },
}

/// Where a flight's tiles come from.
#[cfg(feature = "client")]
#[derive(clap::Args)]
struct TileArgs {
    /// Region configuration (default: the embedded demo region).
    #[arg(long, conflicts_with = "server")]
    config: Option<PathBuf>,
    /// A `sylva serve` to fetch tiles from, e.g. http://127.0.0.1:8080.
    #[arg(long)]
    server: Option<String>,
}

#[cfg(feature = "client")]
impl TileArgs {
    fn open(&self) -> Result<Box<dyn sylva::client::source::TileSource>> {
        Ok(sylva::client::source::open(self.config.as_deref(), self.server.as_deref())?)
    }
}

/// How a flight's frames are rendered and their tiles chosen.
#[cfg(feature = "client")]
#[derive(clap::Args)]
struct RenderArgs {
    /// Image size, WxH.
    #[arg(long, default_value = "640x480")]
    size: String,
    /// `exact` or `linear:STEPS`.
    #[arg(long, default_value = "exact")]
    traversal: String,
    /// Shadow samples per hit (0: none).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(0..=256))]
    shadow_steps: u32,
    /// Tile selection: `sse` (refine to --max-error-px) or `budget`
    /// (the most benefit whose predicted frame time fits --budget-ms).
    #[arg(long, default_value = "sse")]
    lod: String,
    /// Frame budget of `--lod budget`, ms.
    #[arg(long, default_value_t = 33.0)]
    budget_ms: f64,
    /// Frames between selections of `--lod budget` (the selection
    /// thread's period).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    select_every: u32,
    /// Geomorph between tile levels over the selection period (`--lod
    /// budget`; a morphing tile is prepared and uploaded once, with the
    /// coarser surface the GPU blends it with).
    #[arg(long)]
    geomorph: bool,
    /// The cost model `--lod budget` starts from: the `cost_model.json`
    /// an earlier flight on this machine calibrated (default: constants
    /// for a current GPU).
    #[arg(long)]
    cost_model: Option<PathBuf>,
    /// Largest projected tile error, pixels.
    #[arg(long, default_value_t = 2.0, value_parser = positive_px)]
    max_error_px: f64,
    /// Deepest tile level.
    #[arg(long, default_value_t = 13)]
    max_level: u32,
    /// GPU tile cache budget, MiB.
    #[arg(long, default_value_t = 512, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    gpu_budget_mib: usize,
    /// Draw the canopy by ray casting alone, without trees as point
    /// splats near the camera.
    #[arg(long)]
    no_trees: bool,
    /// Hull quads this many times the tiles' 16 samples: fewer
    /// triangles, for software rasterisers (lavapipe: 4 gives ~30 %
    /// faster frames; rays start farther from the surface, so more
    /// fetches, and the linear march misses more).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=32))]
    hull_factor: u32,
    /// Where rays are cast: `fragment` (from each tile's hull) or
    /// `compute` (compute passes; for GPUs that shade fragments on a
    /// small part of the chip, such as data-centre GPUs).
    #[arg(long, default_value = "fragment")]
    ray_pass: RayPass,
}

#[cfg(feature = "client")]
impl RenderArgs {
    /// The flight options these arguments set (the rest default).
    fn options(&self) -> Result<sylva::client::fly::FlyOptions> {
        let mode = match self.lod.as_str() {
            "sse" if self.geomorph || self.select_every != 1 || self.cost_model.is_some() => {
                bail!("--geomorph, --select-every and --cost-model apply to --lod budget only, not to --lod sse")
            }
            "sse" => sylva::client::fly::LodMode::Sse,
            "budget" if self.budget_ms.is_finite() && self.budget_ms > 0.0 => sylva::client::fly::LodMode::Budget {
                budget_ms: self.budget_ms,
                select_every: self.select_every,
                prior: self.prior()?,
            },
            "budget" => bail!("--budget-ms {} is not a positive number of milliseconds", self.budget_ms),
            other => bail!("unknown --lod {other:?}; expected sse or budget"),
        };
        let traversal = sylva::client::fly::parse_traversal(&self.traversal)
            .ok_or_else(|| anyhow::anyhow!("unknown traversal {:?}; expected exact or linear:STEPS", self.traversal))?;
        Ok(sylva::client::fly::FlyOptions {
            size: parse_size(&self.size)?,
            traversal,
            shadow_steps: self.shadow_steps,
            lod: sylva::client::quadtree::LodRule { max_error_px: self.max_error_px, max_level: self.max_level },
            mode,
            geomorph: self.geomorph,
            trees: if self.no_trees { None } else { Some(Default::default()) },
            hull_factor: self.hull_factor as usize,
            ray_pass: self.ray_pass,
            ..Default::default()
        })
    }

    /// The cost model a budget flight starts from.
    fn prior(&self) -> Result<sylva::lod::model::CostModel> {
        let Some(file) = &self.cost_model else { return Ok(Default::default()) };
        let text = std::fs::read_to_string(file).with_context(|| format!("{}", file.display()))?;
        sylva::lod::model::CostModel::from_json(&text).map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))
    }
}

/// `sylva seed`.
#[cfg(feature = "server")]
#[derive(clap::Args)]
struct SeedArgs {
    /// Region and tile cache configuration (default: the embedded demo region).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Tile cache directory (default: `[tile_cache]`).
    #[arg(long)]
    cache_dir: Option<PathBuf>,
    /// Layers, comma-separated: dem, cover, canopy, cem, surface, max4, max32.
    #[arg(long, default_value = "cem")]
    layers: String,
    /// Formats, comma-separated: bil16 (.bil), bil32, png16 (.png), tiff (.tif).
    #[arg(long, default_value = "bil16")]
    formats: String,
    /// Levels, FROM-TO or one level.
    #[arg(long)]
    levels: Option<String>,
    /// W,S,E,N in degrees (default: the region's bounds).
    #[arg(long, allow_hyphen_values = true, conflicts_with = "coverage")]
    bbox: Option<String>,
    /// GeoJSON Polygons or MultiPolygons (holes allowed) instead of a box.
    #[arg(long)]
    coverage: Option<PathBuf>,
    /// Seed the tiles listed in FILE (layer/level/row/col per line), e.g. a failed-tiles file.
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
    /// Seed part I (0-based) of N disjoint parts.
    #[arg(long)]
    shard: Option<String>,
    /// Compute every tile rather than building parents from their children.
    #[arg(long)]
    no_from_children: bool,
    /// Plain log lines instead of a progress bar, or nothing.
    #[arg(long, value_parser = ["auto", "plain", "quiet"], default_value = "auto")]
    progress: String,
}

#[derive(Subcommand)]
enum Bench {
    /// Per-stage tile times, a whole-area build, and error against run time
    /// for resampling, 16-bit encodings and the close.
    Pipeline {
        /// A real-data region with a map-based land cover (default:
        /// config/examples/rmnp.toml, left out when its data is absent).
        #[arg(long)]
        rmnp: Option<PathBuf>,
        /// Forest labels for scoring the close.
        #[arg(long, default_value = "tests/fixtures/rmnp_forest_labels.csv")]
        labels: PathBuf,
        /// Side of the whole-area build.
        #[arg(long, default_value_t = 4096)]
        build_side: usize,
    },
    /// LOD selection along flyovers of the demo region and rmnp: selection
    /// time with and without variable splitting and the deferral table,
    /// benefit against the optimiser's upper bound.
    Lod {
        /// A real-data region (default: config/examples/rmnp.toml, left out
        /// when its data is absent).
        #[arg(long)]
        rmnp: Option<PathBuf>,
        /// Frames per flyover.
        #[arg(long, default_value_t = 300)]
        frames: usize,
        /// Where to write the plots (lod_demo.png, lod_rmnp.png).
        #[arg(long)]
        plots: Option<PathBuf>,
        /// Output directories of `sylva fly --lod budget`: their predicted
        /// and measured frame times against the budget.
        #[arg(long, num_args = 0..)]
        flights: Vec<PathBuf>,
    },
    /// The client's screen-space error selection along the recorded
    /// flyovers: nodes touched with the deferral table against full
    /// re-evaluation every frame (equal selections checked).
    Sse {
        /// A real-data region (default: config/examples/rmnp.toml, left out
        /// when its data is absent).
        #[arg(long)]
        rmnp: Option<PathBuf>,
        /// Directory of the camera paths (`demo_*.toml`, `rmnp_*.toml`).
        #[arg(long, default_value = "config/paths")]
        paths: PathBuf,
        /// Frames per second of each path's own time (a real-time flight).
        #[arg(long, default_value_t = 60.0, conflicts_with = "frames")]
        fps: f64,
        /// Frames per path instead, spread over it whatever its length.
        #[arg(long)]
        frames: Option<usize>,
    },
    /// The server over loopback HTTP beside MapServer and MapProxy: GetMap,
    /// uncached and cached tile latency and throughput, memory.
    #[cfg(feature = "server")]
    Serve {
        /// Configurations of the peers' three DEMs.
        #[arg(long, num_args = 3, default_values = ["config/examples/rmnp.toml", "config/examples/bigtujunga.toml", "config/examples/mt_hood.toml"])]
        configs: Vec<PathBuf>,
        /// MapServer's WMS endpoint (`shared/peers/run_mapserver.sh`).
        #[arg(long, default_value = "http://127.0.0.1:8081/mapserv?")]
        mapserver: String,
        /// MapProxy's base URL (`shared/peers/run_mapproxy.sh`).
        #[arg(long, default_value = "http://127.0.0.1:8083")]
        mapproxy: String,
        /// Warm requests per latency run.
        #[arg(long, default_value_t = 50)]
        n: usize,
        /// Uncached tiles per level, at most.
        #[arg(long, default_value_t = 50)]
        uncached: usize,
        /// Seconds of each wrk run.
        #[arg(long, default_value_t = 10)]
        wrk_seconds: u32,
    },
    /// The ray caster's error against run time: each traversal and shadow
    /// setting on fixed views of the demo and rmnp, against the exact CPU
    /// reference.
    #[cfg(feature = "client")]
    Raycast {
        /// The real-data region (default: config/examples/rmnp.toml).
        #[arg(long)]
        rmnp: Option<PathBuf>,
        /// Image size, WxH.
        #[arg(long, default_value = "1280x1024")]
        size: String,
        /// GPU tile cache budget, MiB.
        #[arg(long, default_value_t = 1024)]
        gpu_budget_mib: usize,
        /// Where to write the plot of error against time.
        #[arg(long, default_value = "docs/raycast-error-vs-time.png")]
        plot: PathBuf,
        /// Run only these settings (e.g. `--only "linear 30 + 10" --only "exact + 10"`); all by default.
        #[arg(long)]
        only: Vec<String>,
        /// Hull fragments without their depth promise (`@early_depth_test`),
        /// for comparison: every hidden fragment casts its ray.
        #[arg(long)]
        no_early_depth: bool,
        /// Where rays are cast: `fragment` or `compute`.
        #[arg(long, default_value = "fragment")]
        ray_pass: RayPass,
    },
    /// Seeding speed (1 and 2 workers, parents from children or not) and
    /// memory over a ~100,000-tile job.
    #[cfg(feature = "server")]
    Seed {
        /// The region.
        #[arg(long, default_value = "config/examples/rmnp.toml")]
        config: PathBuf,
        /// Levels of the speed runs.
        #[arg(long, default_value = "0-12")]
        levels: String,
        /// Levels of the memory run.
        #[arg(long, default_value = "5-12")]
        memory_levels: String,
        /// mapproxy-seed's tiles per second in this sitting (benches/seed.sh), for the ratio.
        #[arg(long)]
        mapproxy_rate: Option<f64>,
    },
    /// Mixed load on one server for a while, printing resident memory.
    #[cfg(feature = "server")]
    Soak {
        /// Region configuration (default: the embedded demo region).
        #[arg(long)]
        config: Option<PathBuf>,
        /// How long, minutes.
        #[arg(long, default_value_t = 10.0)]
        minutes: f64,
        /// Seconds between memory readings.
        #[arg(long, default_value_t = 30.0)]
        every: f64,
    },
}

fn main() {
    let cli = Cli::parse();
    logs(&cli.command);
    if let Err(e) = run(cli.command) {
        eprintln!("sylva: {}", explain(&e));
        std::process::exit(1);
    }
}

/// The error and its causes, each cause said once: most errors already
/// write their cause into their own message.
fn explain(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain().map(ToString::to_string) {
        if !text.contains(&cause) {
            text = if text.is_empty() { cause } else { format!("{text}: {cause}") };
        }
    }
    text
}

/// mimalloc's setting for a long-running server: freed memory goes back to
/// the kernel after 50 ms instead of 1 s. Under `sylva bench soak` (10 min)
/// the peak resident memory was 489 MiB instead of 528 MiB, with as many
/// requests served. mimalloc reads its options from the environment when the
/// process starts, so the process re-executes itself once with the variable
/// set (same pid; a variable the caller set is kept). If that fails, the
/// server runs with the defaults.
#[cfg(feature = "server")]
fn with_server_allocator() {
    use std::os::unix::process::CommandExt;
    const VAR: &str = "MIMALLOC_PURGE_DELAY";
    if std::env::var_os(VAR).is_some() {
        return;
    }
    let Ok(exe) = std::env::current_exe() else { return };
    let error = std::process::Command::new(exe).args(std::env::args_os().skip(1)).env(VAR, "50").exec();
    eprintln!("sylva: running with the allocator's defaults ({VAR} not applied: {error})");
}

/// The benchmarks' real-data region when none is named; they leave it out
/// when its data (`../shared/data`) is absent.
const DEFAULT_REAL_REGION: &str = "config/examples/rmnp.toml";

/// The benchmarks' real-data region: a named one must load (the error names
/// the file), where the default may be left out.
fn real_region(named: Option<PathBuf>) -> Result<PathBuf> {
    if let Some(path) = &named {
        sylva::config::load(Some(path))?;
    }
    Ok(named.unwrap_or_else(|| PathBuf::from(DEFAULT_REAL_REGION)))
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Tile { config, layer, level, row, col, halo, format, output } => {
            outputs::check(config.as_deref().as_slice(), &[&output])?;
            let region = sylva::config::load(config.as_deref())?;
            let product = produce::tile(
                &region,
                TileId::new(level, row, col),
                halo,
                parse_layer(&layer)?,
                parse_format(&format)?,
            )?;
            write(&output, &product)
        }
        Command::Build { config, layer, bbox, width, height, format, output } => {
            outputs::check(config.as_deref().as_slice(), &[&output])?;
            let region = sylva::config::load(config.as_deref())?;
            let bbox = match bbox {
                Some(text) => BBox::parse(&text)?,
                None => region.bounds,
            };
            let product = produce::area(&region, bbox, width, height, parse_layer(&layer)?, parse_format(&format)?)?;
            write(&output, &product)
        }
        #[cfg(feature = "server")]
        Command::Serve { config, bind, cache_dir } => {
            with_server_allocator();
            serve(config, sylva::server::ServeOptions { bind, cache_dir })
        }
        #[cfg(feature = "server")]
        Command::Seed(args) => seed(*args),
        Command::Bench { what: Bench::Pipeline { rmnp, labels, build_side } } => {
            let rmnp = real_region(rmnp)?;
            println!("{}", sylva::bench::pipeline_report(&rmnp, &labels, build_side)?);
            Ok(())
        }
        Command::Bench { what: Bench::Lod { rmnp, frames, plots, flights } } => {
            let rmnp = real_region(rmnp)?;
            println!("{}", sylva::bench::lod_report(&rmnp, frames, plots.as_deref(), &flights)?);
            Ok(())
        }
        Command::Bench { what: Bench::Sse { rmnp, paths, fps, frames } } => {
            let rmnp = real_region(rmnp)?;
            use sylva::bench::lod_sse::Pace;
            if !(fps.is_finite() && fps > 0.0) {
                anyhow::bail!("--fps {fps}: a positive number of frames a second");
            }
            let pace = frames.map_or(Pace::PerSecond(fps), Pace::Frames);
            println!("{}", sylva::bench::lod_sse::report(&rmnp, &paths, pace).map_err(anyhow::Error::msg)?);
            Ok(())
        }
        #[cfg(feature = "server")]
        Command::Bench { what: Bench::Serve { configs, mapserver, mapproxy, n, uncached, wrk_seconds } } => {
            with_server_allocator();
            let configs: [PathBuf; 3] =
                configs.try_into().map_err(|_| anyhow::anyhow!("--configs takes three files"))?;
            let bench = sylva::bench::serve::ServeBench { configs, mapserver, mapproxy, n, uncached, wrk_seconds };
            println!("{}", sylva::bench::serve::report(&bench)?);
            Ok(())
        }
        #[cfg(feature = "server")]
        Command::Bench { what: Bench::Seed { config, levels, memory_levels, mapproxy_rate } } => {
            let bench = sylva::bench::seed::SeedBench { config, levels, mapproxy_rate, memory_levels };
            println!("{}", sylva::bench::seed::report(&bench)?);
            Ok(())
        }
        #[cfg(feature = "server")]
        Command::Bench { what: Bench::Soak { config, minutes, every } } => {
            with_server_allocator();
            println!("{}", sylva::bench::serve::soak(config.as_deref(), minutes, every)?);
            Ok(())
        }
        #[cfg(feature = "client")]
        Command::Fly { tiles, path, frames, out, overwrite, no_frames, hold_ms, render } => {
            let options = sylva::client::fly::FlyOptions {
                frames,
                out_dir: Some(out),
                overwrite,
                write_frames: !no_frames,
                hold_ms,
                ..render.options()?
            };
            let path = sylva::client::path::CameraPath::load(&path)?;
            let source = tiles.open()?;
            let budget = render.gpu_budget_mib << 20;
            let records = sylva::client::fly::run(source.as_ref(), &path, &options, budget)?;
            println!("{}", sylva::client::fly::summary(&records));
            Ok(())
        }
        #[cfg(feature = "window")]
        Command::View { tiles, path, frames, out, overwrite, render } => {
            if let Some(dir) = &out {
                // Refused here, before the window opens; replaced on closing.
                sylva::client::fly::prepare_out_dir(dir, overwrite)?;
            }
            let source = tiles.open()?;
            let path = path.as_deref().map(sylva::client::path::CameraPath::load).transpose()?;
            let start = match &path {
                Some(path) => sylva::client::view::path_start(path),
                None => sylva::client::view::default_start(source.as_ref())?,
            };
            let options = sylva::client::view::ViewOptions {
                render: sylva::client::fly::FlyOptions { overwrite, ..render.options()? },
                start,
                fov_deg: path.as_ref().map_or(sylva::client::view::FOV_DEG, |p| p.fov_deg),
                sun_ecef: match &path {
                    Some(path) => path.sun_ecef(),
                    None => Some(sylva::client::view::SUN.ecef(start.eye.lon_deg, start.eye.lat_deg)),
                },
                gpu_budget_bytes: render.gpu_budget_mib << 20,
                exit_after: frames,
                out_dir: out,
            };
            let records = sylva::client::view::run(source.into(), options)?;
            println!("{}", sylva::client::fly::summary(&records));
            Ok(())
        }
        Command::Canopy { las, resolution, output, chm, preview, crs, tile_px, colours, variants } => {
            let inputs: Vec<&Path> = las.iter().map(PathBuf::as_path).collect();
            let targets: Vec<&Path> =
                [Some(&output), chm.as_ref(), preview.as_ref()].into_iter().flatten().map(PathBuf::as_path).collect();
            outputs::check(&inputs, &targets)?;
            let mut options = sylva::lidar::Options::new(las.clone(), resolution);
            options.crs = crs.as_deref().map(sylva::source::crs::parse_epsg).transpose().map_err(anyhow::Error::msg)?;
            (options.tile_px, options.colours, options.variants) = (tile_px, colours, variants);
            let (model, set) = sylva::lidar::build(&options)?;
            let mut files = vec![(output.as_path(), model.proxy_tiff(&set)?)];
            if let Some(path) = &chm {
                files.push((path, model.chm_tiff()?));
            }
            if let Some(path) = &preview {
                files.push((path, model.preview_png(&set, 3, 0)?));
            }
            outputs::write_all(&files.iter().map(|(p, b)| (*p, b.as_slice())).collect::<Vec<_>>())?;
            println!("{}", model.report(&set));
            Ok(())
        }
        #[cfg(feature = "client")]
        Command::Bench {
            what: Bench::Raycast { rmnp, size, gpu_budget_mib, plot, only, no_early_depth, ray_pass },
        } => {
            let size = parse_size(&size)?;
            let rmnp = real_region(rmnp)?;
            outputs::check(&[], &[&plot])?;
            let mut gpu = sylva::client::render::gpu::Gpu::open()?;
            gpu.early_depth &= !no_early_depth;
            let early = if gpu.early_depth { "on" } else { "off" };
            let name = format!("{}, rays in {ray_pass:?} passes, early depth {early}", gpu.describe());
            let mut renderer =
                sylva::client::render::Renderer::new(gpu, 513, 32, gpu_budget_mib << 20, false).with_ray_pass(ray_pass);
            let views = sylva::bench::raycast::default_views(&rmnp);
            let rows = sylva::bench::raycast::run(&views, size, &only, &mut renderer).map_err(anyhow::Error::msg)?;
            println!("{}", sylva::bench::raycast::report(&rows, size, &name));
            outputs::write_all(&[(&plot, &sylva::bench::raycast::plot(&rows).map_err(anyhow::Error::msg)?)])?;
            eprintln!("plot: {}", plot.display());
            Ok(())
        }
        Command::Info { config } => {
            println!("{}", sylva::config::load(config.as_deref())?.describe());
            Ok(())
        }
    }
}

/// Logs to stderr, filtered by `RUST_LOG`: by default the server's `info`;
/// for the other commands sylva's warnings only (a tile server being
/// retried, say): the GPU and window stacks report probes that fail as a
/// matter of course as errors (wgpu's EGL probe, winit's X11 settings); JSON
/// lines with `SYLVA_LOG_FORMAT=json`.
fn logs(command: &Command) {
    let default = match command {
        #[cfg(feature = "server")]
        Command::Serve { .. } => "info,tower_http=warn",
        _ => "sylva=warn",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| default.into());
    let logs = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr);
    if std::env::var("SYLVA_LOG_FORMAT").is_ok_and(|f| f.eq_ignore_ascii_case("json")) {
        logs.json().init();
    } else {
        logs.with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr())).init();
    }
}

/// Serves until SIGTERM.
#[cfg(feature = "server")]
fn serve(config: Option<PathBuf>, options: sylva::server::ServeOptions) -> Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(sylva::server::serve(config.as_deref(), options))
}

/// Parses `WxH`.
#[cfg(feature = "client")]
fn parse_size(text: &str) -> Result<(u32, u32)> {
    let parsed = text.split_once(['x', 'X']).and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)));
    match parsed {
        Some((w, h)) if (1..=16384).contains(&w) && (1..=16384).contains(&h) => Ok((w, h)),
        _ => bail!("bad size {text:?}; expected WxH, each 1 to 16384, e.g. 640x480"),
    }
}

/// Runs a seed; a run with failed tiles exits with status 3.
#[cfg(feature = "server")]
fn seed(a: SeedArgs) -> Result<()> {
    use sylva::seed::display::Mode;
    let display = match a.progress.as_str() {
        "plain" => Mode::Plain,
        "quiet" => Mode::Quiet,
        _ => Mode::Auto,
    };
    let options = sylva::seed::SeedOptions {
        config: a.config,
        cache_dir: a.cache_dir,
        layers: a.layers,
        formats: a.formats,
        levels: a.levels,
        bbox: a.bbox,
        coverage: a.coverage,
        tiles_from: a.tiles_from,
        dry_run: a.dry_run,
        concurrency: a.concurrency,
        resume: a.resume,
        progress_file: a.progress_file,
        failed_file: a.failed_file,
        refresh_before: a.refresh_before,
        skip_existing: a.skip_existing,
        retries: a.retries,
        max_failures: a.max_failures,
        shard: a.shard,
        from_children: !a.no_from_children,
        display,
    };
    let report = sylva::seed::run(&options, &sylva::seed::Counters::default())?;
    println!("{}", report.text);
    if report.failed > 0 {
        std::process::exit(3);
    }
    Ok(())
}

/// A finite number of pixels above 0.
#[cfg(feature = "client")]
fn positive_px(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("{text:?} is not a positive number of pixels")),
    }
}

fn parse_layer(text: &str) -> Result<Layer> {
    match Layer::parse(text) {
        Some(l) => Ok(l),
        None => bail!("unknown layer {text:?}; expected one of dem, cover, canopy, cem, surface, max4, max32"),
    }
}

fn parse_format(text: &str) -> Result<Format> {
    match Format::parse(text) {
        Some(f) => Ok(f),
        None => bail!("unknown format {text:?}; expected bil16, bil32, png16 or tiff"),
    }
}

/// Writes the product atomically and reports it.
fn write(path: &Path, product: &Product) -> Result<()> {
    outputs::write_all(&[(path, &product.encoded.bytes)])?;
    let g = &product.grid;
    eprintln!(
        "{}: {}×{} samples, {} bytes, {:.1} ms",
        path.display(),
        g.width(),
        g.height(),
        product.encoded.bytes.len(),
        product.stats.total().as_secs_f64() * 1e3
    );
    if let Some(q) = product.encoded.quantization {
        eprintln!("  16-bit codes: value = {} + {} · code", q.offset, q.scale);
    }
    if product.encoded.clamped > 0 {
        eprintln!("  warning: {} samples were outside the 16-bit range and were clamped", product.encoded.clamped);
    }
    Ok(())
}
