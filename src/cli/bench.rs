//! `sylva bench`: each benchmark's arguments, its run, and its table
//! printed to stdout.

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;
#[cfg(feature = "client")]
use sylva::client::render::RayPass;

#[derive(Subcommand)]
pub enum Bench {
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
        /// Frames per flyover (3 or more: a third of them are swept).
        #[arg(long, default_value_t = 300, value_parser = clap::value_parser!(u32).range(3..))]
        frames: u32,
        /// Where to write the plots (lod_demo.png, lod_rmnp.png, and
        /// lod_frames_NAME.png of each --flights directory).
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
        #[arg(long, default_value_t = 60.0, conflicts_with = "frames", value_parser = super::positive("frames a second"))]
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
    Raycast(RaycastArgs),
    /// Seeding speed (World Wind tiles on 1 and 2 workers, parents from
    /// children or not; XYZ, WMTS CRS84 and Cesium tiles) and memory over a
    /// ~155,000-tile job.
    #[cfg(feature = "server")]
    Seed {
        /// The region.
        #[arg(long, default_value = "config/examples/rmnp.toml")]
        config: PathBuf,
        /// Levels of the speed runs.
        #[arg(long, default_value = "0-12")]
        levels: String,
        /// Zooms of the memory run's XYZ dem tiles of the demo region.
        #[arg(long, default_value = "0-19")]
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

/// Where `sylva bench raycast` writes its plot unless told: in the
/// repository's docs.
#[cfg(feature = "client")]
const DEFAULT_RAYCAST_PLOT: &str = "docs/raycast-error-vs-time.png";

/// `sylva bench raycast`.
#[cfg(feature = "client")]
#[derive(clap::Args)]
pub struct RaycastArgs {
    /// The real-data region (default: config/examples/rmnp.toml).
    #[arg(long)]
    rmnp: Option<PathBuf>,
    /// Image size, WxH (each 1 to 16384).
    #[arg(long, default_value = "1280x1024", value_parser = super::flight::size_px)]
    size: (u32, u32),
    /// GPU tile cache budget, MiB (at most 1 TiB).
    #[arg(long, default_value_t = 1024, value_parser = super::flight::gpu_budget_mib())]
    gpu_budget_mib: usize,
    /// Where to write the plot of error against time (default: the
    /// repository's docs/raycast-error-vs-time.png, for the whole run of
    /// the documented settings only, which it records).
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Run only these settings (e.g. `--only "linear 30 + 10" --only "exact + 10"`); all by default.
    #[arg(long, value_parser = sylva::bench::raycast::setting_named)]
    only: Vec<String>,
    /// Hull fragments without their depth promise (`@early_depth_test`),
    /// for comparison: every hidden fragment casts its ray.
    #[arg(long)]
    no_early_depth: bool,
    /// Where rays are cast: `fragment` or `compute`.
    #[arg(long, default_value = "fragment")]
    ray_pass: RayPass,
}

impl Bench {
    pub fn run(self) -> Result<()> {
        match self {
            Bench::Pipeline { rmnp, labels, build_side } => {
                let rmnp = real_region(rmnp)?;
                super::print(sylva::bench::pipeline_report(&rmnp, &labels, build_side)?)?;
            }
            Bench::Lod { rmnp, frames, plots, flights } => {
                let rmnp = real_region(rmnp)?;
                if let Some(dir) = &plots {
                    // Refused before the flyovers, not after them.
                    sylva::outputs::check(&[], &[&dir.join("lod_demo.png")])?;
                }
                let written = sylva::bench::lod_report(
                    &rmnp,
                    frames as usize,
                    (plots.as_deref(), &flights),
                    &mut std::io::stdout(),
                );
                match written {
                    Err(sylva::bench::LodReportError::Print(e)) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
                    written => written?,
                }
            }
            Bench::Sse { rmnp, paths, fps, frames } => {
                let rmnp = real_region(rmnp)?;
                use sylva::bench::lod_sse::Pace;
                let pace = frames.map_or(Pace::PerSecond(fps), Pace::Frames);
                super::print(sylva::bench::lod_sse::report(&rmnp, &paths, pace).map_err(anyhow::Error::msg)?)?;
            }
            #[cfg(feature = "server")]
            Bench::Serve { configs, mapserver, mapproxy, n, uncached, wrk_seconds } => {
                super::serving::with_server_allocator();
                let configs: [PathBuf; 3] =
                    configs.try_into().map_err(|_| anyhow::anyhow!("--configs takes three files"))?;
                let bench = sylva::bench::serve::ServeBench { configs, mapserver, mapproxy, n, uncached, wrk_seconds };
                super::print(sylva::bench::serve::report(&bench)?)?;
            }
            #[cfg(feature = "server")]
            Bench::Seed { config, levels, memory_levels, mapproxy_rate } => {
                let bench = sylva::bench::seed::SeedBench { config, levels, mapproxy_rate, memory_levels };
                super::print(sylva::bench::seed::report(&bench)?)?;
            }
            #[cfg(feature = "server")]
            Bench::Soak { config, minutes, every } => {
                super::serving::with_server_allocator();
                super::print(sylva::bench::serve::soak(config.as_deref(), minutes, every)?)?;
            }
            #[cfg(feature = "client")]
            Bench::Raycast(args) => args.run()?,
        }
        Ok(())
    }
}

#[cfg(feature = "client")]
impl RaycastArgs {
    /// The table to stdout, the plot to its file.
    fn run(self) -> Result<()> {
        use sylva::bench::raycast;
        let size = self.size;
        let plot = self.plot_path();
        let rmnp = real_region(self.rmnp)?;
        let views = raycast::default_views(&rmnp);
        if let Some(view) = views.iter().find(|v| !v.path.is_file()) {
            anyhow::bail!(
                "{}: no such file; bench raycast reads its views' camera paths from config/paths/ in the current directory: run it from the repository root",
                view.path.display()
            );
        }
        if let Some(plot) = &plot {
            sylva::outputs::check(&[], &[plot]).map_err(|e| match self.plot.is_none() {
                true => anyhow::anyhow!("{e} (the default --plot, {DEFAULT_RAYCAST_PLOT}, is in the repository; run from its root, or give --plot FILE)"),
                false => e.into(),
            })?;
        }
        let mut gpu = sylva::client::render::gpu::Gpu::open()?;
        gpu.early_depth &= !self.no_early_depth;
        let early = if gpu.early_depth { "on" } else { "off" };
        let name = format!("{}, rays in {:?} passes, early depth {early}", gpu.describe(), self.ray_pass);
        let budget = self.gpu_budget_mib << 20;
        let mut renderer =
            sylva::client::render::Renderer::new(gpu, 513, 32, budget, false)?.with_ray_pass(self.ray_pass);
        let rows = raycast::run(&views, size, &self.only, &mut renderer).map_err(anyhow::Error::msg)?;
        super::print(raycast::report(&rows, size, &name))?;
        match plot {
            Some(plot) => {
                sylva::outputs::write_all(&[(&plot, &raycast::plot(&rows).map_err(anyhow::Error::msg)?)])?;
                sylva::outputs::say(format_args!("plot: {}", plot.display()));
            }
            None => sylva::outputs::say(format_args!(
                "plot: not written (a partial run would replace {DEFAULT_RAYCAST_PLOT}; --plot FILE writes it)"
            )),
        }
        Ok(())
    }

    /// Where the plot goes: where told, else the repository's own for the
    /// documented run (every setting, 1280×1024, fragments with early
    /// depth), else nowhere.
    fn plot_path(&self) -> Option<PathBuf> {
        let documented = self.only.is_empty()
            && self.size == (1280, 1024)
            && self.ray_pass == RayPass::Fragment
            && !self.no_early_depth
            && self.rmnp.is_none();
        self.plot.clone().or_else(|| documented.then(|| PathBuf::from(DEFAULT_RAYCAST_PLOT)))
    }
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
