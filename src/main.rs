//! The `sylva` command line: parses arguments, calls the library, writes
//! files, and maps errors to messages and exit codes (1: bad input or data,
//! 2: bad usage, from clap; 3: a seed finished with failed tiles; 128 + the
//! signal: a seed or a flight stopped by Ctrl-C or SIGTERM). Each
//! command's arguments and run live in `cli/`.

mod cli;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// Tiles allocate and free megabyte rasters at a high rate; glibc returns
/// them to the kernel each time and pays a page fault per 4 KiB on reuse
/// (22 % of a warm tile's time, measured with perf). mimalloc keeps them.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

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
    Tile(cli::produce::TileArgs),
    /// Compute a layer over a whole box in one go (the reference tiles match).
    Build(cli::produce::BuildArgs),
    /// Serve WMS, WMTS, World Wind, XYZ tiles and Cesium terrain over HTTP.
    #[cfg(feature = "server")]
    Serve(cli::serving::ServeArgs),
    /// Fly a camera path headless: PNG frames and per-frame statistics.
    #[cfg(feature = "client")]
    Fly(Box<cli::flight::FlyArgs>),
    /// Fly over the tiles in a window, with keyboard and mouse (W/S/A/D
    /// move, Q/E down and up, arrows and a left drag look, Shift and the
    /// wheel set the speed, L sun, T traversal, P saves the frame, Esc quits).
    #[cfg(feature = "window")]
    View(Box<cli::flight::ViewArgs>),
    /// Pregenerate tiles into the tile cache (resumable, parallel, sharded).
    #[cfg(feature = "server")]
    Seed(Box<cli::serving::SeedArgs>),
    /// What the tile cache holds per version; remove stale versions and
    /// trim it to a size.
    #[cfg(feature = "server")]
    Cache {
        #[command(subcommand)]
        what: cli::cache::CacheCommand,
    },
    /// Print benchmark tables.
    Bench {
        #[command(subcommand)]
        what: cli::bench::Bench,
    },
    /// Build a canopy proxy (Wang tiles) from LiDAR point clouds.
    Canopy(Box<cli::produce::CanopyArgs>),
    /// Describe the region a configuration makes.
    Info(cli::produce::InfoArgs),
}

fn main() {
    let cli = Cli::parse();
    logs(&cli.command);
    if let Err(e) = run(cli.command) {
        // A usage error found after parsing reads as clap's own (exit 2).
        let e = match e.downcast::<clap::Error>() {
            Ok(usage) => usage.exit(),
            Err(e) => e,
        };
        sylva::outputs::say(format_args!("sylva: {}", explain(&e)));
        std::process::exit(1);
    }
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Tile(args) => args.run(),
        Command::Build(args) => args.run(),
        #[cfg(feature = "server")]
        Command::Serve(args) => args.run(),
        #[cfg(feature = "client")]
        Command::Fly(args) => args.run(),
        #[cfg(feature = "window")]
        Command::View(args) => args.run(),
        #[cfg(feature = "server")]
        Command::Seed(args) => args.run(),
        #[cfg(feature = "server")]
        Command::Cache { what } => what.run(),
        Command::Bench { what } => what.run(),
        Command::Canopy(args) => args.run(),
        Command::Info(args) => args.run(),
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

/// Logs to stderr, filtered by `RUST_LOG`: by default the server's `info`;
/// for the other commands sylva's warnings only (a tile server being
/// retried, say): the GPU and window stacks report probes that fail as a
/// matter of course as errors (wgpu's EGL probe, winit's X11 settings); JSON
/// lines with `SYLVA_LOG_FORMAT=json`.
fn logs(command: &Command) {
    let default = match command {
        #[cfg(feature = "server")]
        Command::Serve(_) => "info,tower_http=warn",
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
