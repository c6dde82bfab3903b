//! The commands that render flights over the tiles: `fly` (headless, a
//! camera path to PNG frames and statistics) and `view` (in a window).

use anyhow::{Context, Result};
use std::path::PathBuf;
use sylva::client::fly::{self, FlyOptions};
use sylva::client::render::RayPass;

/// Where a flight's tiles come from.
#[derive(clap::Args)]
pub struct SourceArgs {
    /// Region configuration (default: the embedded demo region).
    #[arg(long, conflicts_with = "server")]
    config: Option<PathBuf>,
    /// A `sylva serve` to fetch tiles from, e.g. http://127.0.0.1:8080.
    #[arg(long)]
    server: Option<String>,
}

impl SourceArgs {
    fn open(&self) -> Result<Box<dyn sylva::client::source::TileSource>> {
        Ok(sylva::client::source::open(self.config.as_deref(), self.server.as_deref())?)
    }
}

/// `sylva fly`.
#[derive(clap::Args)]
pub struct FlyArgs {
    #[command(flatten)]
    tiles: SourceArgs,
    /// Camera path (TOML; see config/paths/).
    #[arg(long)]
    path: PathBuf,
    /// Frames spread evenly over the path (1 to a million).
    #[arg(long, default_value_t = 60, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1_000_000))]
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
    #[arg(long, default_value_t = 0.0, value_parser = hold_ms)]
    hold_ms: f64,
    #[command(flatten)]
    render: RenderArgs,
}

impl FlyArgs {
    pub fn run(self) -> Result<()> {
        let options = FlyOptions {
            frames: self.frames,
            out_dir: Some(self.out),
            overwrite: self.overwrite,
            watch_signals: true,
            write_frames: !self.no_frames,
            hold_ms: self.hold_ms,
            ..self.render.options()?
        };
        let path = sylva::client::path::CameraPath::load(&self.path)?;
        let source = self.tiles.open()?;
        let budget = self.render.gpu_budget_mib << 20;
        let records = match fly::run(source.as_ref(), &path, &options, budget) {
            // Stopped by a signal: the status a shell gives a death by it.
            Err(e) if let Some(signal) = e.signal() => {
                sylva::outputs::say(format_args!("sylva: {e}"));
                std::process::exit(128 + signal)
            }
            records => records?,
        };
        super::print(fly::summary(&records, options.lod.max_error_px, source.why_no_tile().as_deref()))?;
        Ok(())
    }
}

/// `--gpu-budget-mib`: 1 MiB to 1 TiB.
pub fn gpu_budget_mib() -> clap::builder::RangedU64ValueParser<usize> {
    clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1 << 20)
}

/// Most `--hold-ms`: a frame held a minute measures nothing more.
const MAX_HOLD_MS: f64 = 60_000.0;

/// `--hold-ms`: 0 to [`MAX_HOLD_MS`].
fn hold_ms(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(ms) if (0.0..=MAX_HOLD_MS).contains(&ms) => Ok(ms),
        _ => Err(format!("not 0 to {MAX_HOLD_MS} milliseconds")),
    }
}

/// `sylva view`.
#[cfg(feature = "window")]
#[derive(clap::Args)]
pub struct ViewArgs {
    #[command(flatten)]
    tiles: SourceArgs,
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
}

#[cfg(feature = "window")]
impl ViewArgs {
    pub fn run(self) -> Result<()> {
        // Watched from before the directory is checked: a signal while the
        // view starts closes it as one while it runs does.
        let interrupt = sylva::interrupt::Interrupt::watch();
        // Bad options are refused before any work.
        let render = self.render.options()?;
        // Refused here, before the window opens; replaced on closing.
        let earlier = self.out.as_deref().map(|dir| fly::prepare_out_dir(dir, self.overwrite)).transpose()?;
        match self.view(render, interrupt, earlier.unwrap_or_default())? {
            // Closed by a signal: the status a shell gives a death by it.
            Some(signal) => std::process::exit(128 + signal),
            None => Ok(()),
        }
    }

    /// Opens the window and views until it closes; the signal that closed
    /// it, if one did.
    fn view(
        self,
        render: FlyOptions,
        interrupt: sylva::interrupt::Interrupt,
        earlier: Vec<PathBuf>,
    ) -> Result<Option<i32>> {
        use sylva::client::view;
        let source: std::sync::Arc<dyn sylva::client::source::TileSource> = self.tiles.open()?.into();
        let path = self.path.as_deref().map(sylva::client::path::CameraPath::load).transpose()?;
        let options = view::ViewOptions {
            render: FlyOptions { overwrite: self.overwrite, ..render },
            start: path.as_ref().map(view::path_start),
            fov_deg: path.as_ref().map_or(view::FOV_DEG, |p| p.fov_deg),
            sun: path.as_ref().map_or(Some(view::SUN), |p| p.sun),
            gpu_budget_bytes: self.render.gpu_budget_mib << 20,
            exit_after: self.frames,
            out_dir: self.out,
            earlier,
        };
        let asked_px = options.render.lod.max_error_px;
        let summary = |records: &[fly::FrameRecord]| fly::summary(records, asked_px, source.why_no_tile().as_deref());
        match view::run(source.clone(), options, interrupt) {
            Err(view::ViewError::Interrupted { signal, kept, records }) => {
                super::print(summary(&records))?;
                sylva::outputs::say(format_args!("sylva: view closed by signal {signal}{kept}"));
                Ok(Some(signal))
            }
            records => super::print(summary(&records?)).map(|()| None),
        }
    }
}

/// How a flight's frames are rendered and their tiles chosen.
#[derive(clap::Args)]
pub struct RenderArgs {
    /// Image size, WxH (each 1 to 16384).
    #[arg(long, default_value = "640x480", value_parser = size_px)]
    size: (u32, u32),
    /// `exact` or `linear:STEPS` (STEPS 1 to 4096).
    #[arg(long, default_value = "exact", value_parser = traversal)]
    traversal: sylva::client::raycast::Traversal,
    /// Shadow samples per hit (0: none).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(0..=256))]
    shadow_steps: u32,
    /// Tile selection.
    #[arg(long, value_enum, default_value_t = Lod::Sse)]
    lod: Lod,
    /// Frame budget of `--lod budget`, ms [default: 33]; also the most a
    /// selection may take (then it keeps its best answer so far).
    #[arg(long, value_parser = super::positive("milliseconds"))]
    budget_ms: Option<f64>,
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
    #[arg(long, default_value_t = 2.0, value_parser = super::positive("pixels"))]
    max_error_px: f64,
    /// Deepest tile level.
    #[arg(long, default_value_t = 13, value_parser = clap::value_parser!(u32).range(0..=i64::from(sylva::grid::TileGrid::MAX_LEVEL)))]
    max_level: u32,
    /// GPU tile cache budget, MiB (at most 1 TiB).
    #[arg(long, default_value_t = 512, value_parser = gpu_budget_mib())]
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

impl RenderArgs {
    /// The flight options these arguments set (the rest default).
    fn options(&self) -> Result<FlyOptions> {
        let budget_only =
            self.budget_ms.is_some() || self.geomorph || self.select_every != 1 || self.cost_model.is_some();
        let mode = match self.lod {
            Lod::Sse if budget_only => {
                return Err(super::usage(
                    "--budget-ms, --geomorph, --select-every and --cost-model apply to --lod budget only, not to --lod sse",
                ));
            }
            Lod::Sse => fly::LodMode::Sse,
            Lod::Budget => fly::LodMode::Budget {
                budget_ms: self.budget_ms.unwrap_or(33.0),
                select_every: self.select_every,
                prior: self.prior()?,
            },
        };
        Ok(FlyOptions {
            size: self.size,
            traversal: self.traversal,
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

/// `--lod`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Lod {
    /// Refine to `--max-error-px`.
    Sse,
    /// The most benefit whose predicted frame time fits `--budget-ms`.
    Budget,
}

/// `--size`: `WxH`, each 1 to 16384.
pub fn size_px(text: &str) -> Result<(u32, u32), String> {
    let parsed = text.split_once(['x', 'X']).and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)));
    match parsed {
        Some((w, h)) if (1..=16384).contains(&w) && (1..=16384).contains(&h) => Ok((w, h)),
        _ => Err("not WxH, each 1 to 16384, e.g. 640x480".into()),
    }
}

/// `--traversal`: `exact` or `linear:STEPS`.
fn traversal(text: &str) -> Result<sylva::client::raycast::Traversal, String> {
    let steps = fly::MAX_LINEAR_STEPS;
    fly::parse_traversal(text).ok_or_else(|| format!("not exact or linear:STEPS, STEPS 1 to {steps}"))
}
