//! The `sylva` command line: parses arguments, calls the library, writes
//! files, and maps errors to messages and exit codes (1: bad input or data,
//! 2: bad usage, from clap).

use anyhow::{Context, Result, bail};

/// Tiles allocate and free megabyte rasters at a high rate; glibc returns
/// them to the kernel each time and pays a page fault per 4 KiB on reuse
/// (22 % of a warm tile's time, measured with perf). mimalloc keeps them.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};
use sylva::cem::Layer;
use sylva::encode::Format;
use sylva::grid::{BBox, TileId};
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
        /// Tile cache directory (default: `[server] cache_dir`).
        #[arg(long)]
        cache_dir: Option<PathBuf>,
    },
    /// Print benchmark tables.
    Bench {
        #[command(subcommand)]
        what: Bench,
    },
    /// Describe the region a configuration makes.
    Info {
        /// Region configuration (default: the embedded demo region).
        #[arg(long)]
        config: Option<PathBuf>,
    },
}

#[derive(Subcommand)]
enum Bench {
    /// Per-stage tile times, a whole-area build, and error against run time
    /// for resampling, 16-bit encodings and the close.
    Pipeline {
        /// A real-data region with a map-based land cover.
        #[arg(long, default_value = "config/examples/rmnp.toml")]
        rmnp: PathBuf,
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
        /// A real-data region.
        #[arg(long, default_value = "config/examples/rmnp.toml")]
        rmnp: PathBuf,
        /// Frames per flyover.
        #[arg(long, default_value_t = 300)]
        frames: usize,
        /// Where to write the plots (lod_demo.png, lod_rmnp.png).
        #[arg(long)]
        plots: Option<PathBuf>,
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
    if let Err(e) = run(cli.command) {
        eprintln!("sylva: {e:#}");
        std::process::exit(1);
    }
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Tile { config, layer, level, row, col, halo, format, output } => {
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
            let region = sylva::config::load(config.as_deref())?;
            let bbox = match bbox {
                Some(text) => BBox::parse(&text)?,
                None => region.bounds,
            };
            let product = produce::area(&region, bbox, width, height, parse_layer(&layer)?, parse_format(&format)?)?;
            write(&output, &product)
        }
        #[cfg(feature = "server")]
        Command::Serve { config, bind, cache_dir } => serve(config, sylva::server::ServeOptions { bind, cache_dir }),
        Command::Bench { what: Bench::Pipeline { rmnp, labels, build_side } } => {
            println!("{}", sylva::bench::pipeline_report(&rmnp, &labels, build_side)?);
            Ok(())
        }
        Command::Bench { what: Bench::Lod { rmnp, frames, plots } } => {
            println!("{}", sylva::bench::lod_report(&rmnp, frames, plots.as_deref())?);
            Ok(())
        }
        #[cfg(feature = "server")]
        Command::Bench { what: Bench::Serve { configs, mapserver, mapproxy, n, uncached, wrk_seconds } } => {
            let configs: [PathBuf; 3] =
                configs.try_into().map_err(|_| anyhow::anyhow!("--configs takes three files"))?;
            let bench = sylva::bench::serve::ServeBench { configs, mapserver, mapproxy, n, uncached, wrk_seconds };
            println!("{}", sylva::bench::serve::report(&bench)?);
            Ok(())
        }
        #[cfg(feature = "server")]
        Command::Bench { what: Bench::Soak { config, minutes, every } } => {
            println!("{}", sylva::bench::serve::soak(config.as_deref(), minutes, every)?);
            Ok(())
        }
        Command::Info { config } => {
            println!("{}", sylva::config::load(config.as_deref())?.describe());
            Ok(())
        }
    }
}

/// Logs to stderr (`RUST_LOG` filters, default `info`; JSON lines with
/// `SYLVA_LOG_FORMAT=json`), then serves until SIGTERM.
#[cfg(feature = "server")]
fn serve(config: Option<PathBuf>, options: sylva::server::ServeOptions) -> Result<()> {
    let filter =
        tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info,tower_http=warn".into());
    let logs = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr);
    if std::env::var("SYLVA_LOG_FORMAT").is_ok_and(|f| f.eq_ignore_ascii_case("json")) {
        logs.json().init();
    } else {
        logs.with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr())).init();
    }
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(sylva::server::serve(config.as_deref(), options))
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

/// Writes the product atomically (temporary file, then rename) and reports it.
fn write(path: &Path, product: &Product) -> Result<()> {
    let tmp = path.with_extension("partial");
    std::fs::write(&tmp, &product.encoded.bytes).with_context(|| format!("{}: cannot write", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("{}: cannot rename into place", path.display()))?;
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
