//! `sylva fly`: renders a camera path headless, frame by frame — select
//! tiles (by screen-space error, kept across frames by the deferral table,
//! [`super::sse`], or under a frame budget, [`super::lod`]), load the
//! missing ones ([`super::store`]), ray cast them on the GPU — and records
//! per-frame statistics ([`FrameRecord`]): CPU and GPU time, tiles drawn per level and how, texture fetches per pixel (the ray
//! steps), bytes fetched and memory resident; under a budget also the
//! predicted frame time, which the measured one calibrates, and, asked to,
//! tiles geomorph between levels ([`super::lod::morphs`]). Trees near the
//! camera are drawn as splats ([`super::trees`]): at the resolution their
//! screen size asks for, or under a budget as the selection allots.

mod flight;
mod options;
mod outputs;
mod record;

use super::path::CameraPath;
use super::render::{Readback, RenderError, Renderer};
use super::source::TileSource;
use super::store::LoadError;
use crate::interrupt::Interrupt;
pub use flight::{Flight, Framed, Motion, Shot, Visible, visible_tiles};
use options::MOTION_STEPS;
pub use options::{FlyOptions, LodMode, MAX_LINEAR_STEPS, parse_traversal};
use outputs::{MODEL_FILE, StatsCsv};
pub use outputs::{STATS_FILE, prepare_out_dir, remove_outputs, to_csv, write_png, write_stats};
pub use record::{FrameRecord, summary};
use std::path::PathBuf;

/// Why a flight stopped.
#[derive(Debug, thiserror::Error)]
pub enum FlyError {
    /// A tile could not be loaded.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// The GPU cache cannot hold even the coarsest view, or the frame's
    /// render targets cannot be allocated.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The LOD selection thread could not start.
    #[error("starting the LOD selection thread: {0}")]
    Thread(std::io::Error),
    /// An output file cannot be written (one named as an input found
    /// before the flight starts; a failed write during it).
    #[error(transparent)]
    Output(#[from] crate::outputs::OutputError),
    /// The output directory holds an earlier run's outputs.
    #[error(
        "{0}: holds an earlier flight's or view's outputs ({1}); give another --out, or --overwrite to replace them"
    )]
    Earlier(PathBuf, String),
    /// The flight stopped before its last frame; the frames it finished
    /// and their statistics were written (`kept` says where, or why not).
    #[error("{why}; stopped after {done} of {of} frames{kept}")]
    Stopped {
        /// Why it stopped.
        why: Stop,
        /// Frames finished.
        done: usize,
        /// Frames asked for.
        of: usize,
        /// "; their frames and stats.csv are in DIR", or why not (empty
        /// without an output directory or a frame to keep).
        kept: String,
    },
    /// Writing frames or statistics failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The failure.
        source: std::io::Error,
    },
}

impl FlyError {
    /// The signal (Ctrl-C, SIGTERM) that stopped the flight, if one did.
    pub fn signal(&self) -> Option<i32> {
        match self {
            FlyError::Stopped { why: Stop::Signal(signal), .. } => Some(*signal),
            _ => None,
        }
    }
}

/// Why a flight stopped before its last frame.
#[derive(Debug)]
pub enum Stop {
    /// Ctrl-C or SIGTERM: the signal's number.
    Signal(i32),
    /// An error.
    Failed(Box<FlyError>),
}

impl Stop {
    fn failed(e: FlyError) -> Stop {
        Stop::Failed(Box::new(e))
    }
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Stop::Signal(signal) => write!(f, "interrupted by signal {signal}"),
            Stop::Failed(e) => e.fmt(f),
        }
    }
}

/// Flies `path` over `source`, rendering with `renderer`. A flight that
/// stops early, by an error or by Ctrl-C or SIGTERM, writes the statistics
/// of the frames it finished beside their PNGs and says so
/// ([`FlyError::Stopped`]).
pub fn fly(
    source: &dyn TileSource,
    path: &CameraPath,
    renderer: &mut Renderer,
    options: &FlyOptions,
) -> Result<Vec<FrameRecord>, FlyError> {
    // Watched from before the directory is checked until the results are
    // written: a first Ctrl-C then waits for the start or the frame in hand.
    let interrupt = options.watch_signals.then(Interrupt::watch);
    let mut earlier = match &options.out_dir {
        Some(dir) => prepare_out_dir(dir, options.overwrite)?,
        None => Vec::new(),
    };
    // Replaced whole by this flight's own: the statistics with its first
    // frame; a budget flight's cost model at its end (until then it may be
    // the model this flight started from).
    let budget = matches!(options.mode, LodMode::Budget { .. });
    let replaced = |f: &PathBuf| f.ends_with(STATS_FILE) || (budget && f.ends_with(MODEL_FILE));
    earlier.retain(|f| !replaced(f));
    fly_in(source, path, renderer, options, earlier, interrupt.as_ref())
}

/// [`fly`] in its output directory, which holds `earlier` outputs.
fn fly_in(
    source: &dyn TileSource,
    path: &CameraPath,
    renderer: &mut Renderer,
    options: &FlyOptions,
    mut earlier: Vec<PathBuf>,
    interrupt: Option<&Interrupt>,
) -> Result<Vec<FrameRecord>, FlyError> {
    let frame_s = path.time(1, options.frames) - path.time(0, options.frames);
    let motion = Motion { frame_s, limits: path.motion_limits(MOTION_STEPS), shadows: path.sun.is_some() };
    let mut flight = Flight::new(source, renderer, options, motion)?;
    // Room for a usual flight's records; a longer one grows as it goes.
    let mut records = Vec::with_capacity(options.frames.min(1 << 12));
    let mut stats = options.out_dir.as_deref().map(StatsCsv::new);
    let kept = (&mut earlier, &mut records, stats.as_mut());
    let flown = fly_path(&mut flight, (source, path, renderer), options, kept, interrupt);
    // A frame that failed because of the signal (a server in the same
    // process group stopped by it) was stopped by the signal.
    let stopped = flown.err().map(|why| interrupt.and_then(Interrupt::came).map_or(why, Stop::Signal));
    let model = flight.model();
    match (stopped, &options.out_dir) {
        (None, Some(dir)) => outputs::write_results(dir, &records, model.as_ref()).map(|()| records),
        (None, None) => Ok(records),
        // Nothing done, nothing written: an earlier run's outputs are whole.
        (Some(Stop::Failed(e)), _) if records.is_empty() => Err(*e),
        (Some(why), dir) => {
            let kept = match dir.as_deref().filter(|_| !records.is_empty()) {
                Some(dir) => outputs::keep(dir, &records, model.as_ref(), options.write_frames),
                None => String::new(),
            };
            Err(FlyError::Stopped { why, done: records.len(), of: options.frames, kept })
        }
    }
}

/// Renders the path's frames, each one's PNG and row of `stats` written
/// once it is done, and keeps their records, until the last frame, an
/// error, or Ctrl-C or SIGTERM (after the frame in hand; a second signal
/// ends the process, and what was written stays).
fn fly_path(
    flight: &mut Flight,
    (source, path, renderer): (&dyn TileSource, &CameraPath, &mut Renderer),
    options: &FlyOptions,
    (earlier, records, mut stats): (&mut Vec<PathBuf>, &mut Vec<FrameRecord>, Option<&mut StatsCsv>),
    interrupt: Option<&Interrupt>,
) -> Result<(), Stop> {
    for k in 0..options.frames {
        if let Some(signal) = interrupt.and_then(Interrupt::came) {
            return Err(Stop::Signal(signal));
        }
        let shot = Shot {
            index: k,
            t_s: path.time(k, options.frames),
            camera: path.camera(k, options.frames, options.size),
            sun_ecef: path.sun_ecef(),
        };
        let framed = flight.frame(source, renderer, options, &shot, Readback::All).map_err(Stop::failed)?;
        let png =
            options.out_dir.as_ref().filter(|_| options.write_frames).map(|d| d.join(format!("frame_{k:05}.png")));
        if let Some(png) = &png {
            write_png(png, &framed.rendered, options.size).map_err(Stop::failed)?;
        }
        if let Some(stats) = stats.as_deref_mut() {
            stats.add(&framed.record).map_err(Stop::failed)?;
        }
        // The earlier run's outputs go once this one has a frame to show
        // (written: its PNG replaced the earlier one of the same name).
        earlier.retain(|f| Some(f) != png.as_ref());
        remove_outputs(&std::mem::take(earlier)).map_err(Stop::failed)?;
        records.push(framed.record);
    }
    Ok(())
}

/// Opens the GPU and flies: what `sylva fly` does.
pub fn run(
    source: &dyn TileSource,
    path: &CameraPath,
    options: &FlyOptions,
    gpu_budget_bytes: usize,
) -> Result<Vec<FrameRecord>, RunError> {
    let gpu = super::render::gpu::Gpu::open()?;
    let grid = source.grid();
    let mut renderer = Renderer::new(gpu, grid.samples(), options.halo as u32, gpu_budget_bytes, options.geomorph)?
        .with_hull_factor(options.hull_factor)
        .with_ray_pass(options.ray_pass);
    Ok(fly(source, path, &mut renderer, options)?)
}

/// Why `sylva fly` failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// No GPU.
    #[error(transparent)]
    Gpu(#[from] super::render::gpu::GpuError),
    /// The GPU has not the memory for the tile cache.
    #[error(transparent)]
    Alloc(#[from] super::render::gpu::AllocError),
    /// The flight failed.
    #[error(transparent)]
    Fly(#[from] FlyError),
}

impl RunError {
    /// The signal (Ctrl-C, SIGTERM) that stopped the flight, if one did.
    pub fn signal(&self) -> Option<i32> {
        match self {
            RunError::Fly(e) => e.signal(),
            _ => None,
        }
    }
}
