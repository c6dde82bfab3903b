//! How to fly: the options of a flight ([`FlyOptions`]), how its tiles are
//! chosen ([`LodMode`]) and the traversal's command-line form.

use crate::client::quadtree::LodRule;
use crate::client::raycast::Traversal;
use crate::client::render::RayPass;
use crate::client::trees::TreeSettings;
use crate::lod::model::CostModel;
use std::path::PathBuf;
/// How tiles are chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LodMode {
    /// Refine while the projected error exceeds [`LodRule::max_error_px`].
    Sse,
    /// The most benefit whose predicted frame time fits `budget_ms`.
    Budget {
        /// The frame budget, ms.
        budget_ms: f64,
        /// Frames between selections (the selection period `τ`).
        select_every: u32,
        /// The cost model the flight starts from (one a flight calibrated
        /// on this machine: its `cost_model.json`).
        prior: CostModel,
    },
}

/// Steps of the path sampled for its motion limits (the conservative
/// camera's speed and turn rate).
pub(super) const MOTION_STEPS: usize = 200;

/// How to fly.
#[derive(Clone, Debug)]
pub struct FlyOptions {
    /// Frames spread evenly over the path.
    pub frames: usize,
    /// Image size, pixels.
    pub size: (u32, u32),
    /// Where frames (`frame_NNNNN.png`) and `stats.csv` go, if anywhere.
    pub out_dir: Option<PathBuf>,
    /// Replace an earlier run's outputs in `out_dir` (else refused).
    pub overwrite: bool,
    /// Watch Ctrl-C and SIGTERM (a command's flight): the first stops the
    /// flight after the frame in hand. A library's flight leaves the
    /// process's signals alone.
    pub watch_signals: bool,
    /// Write every frame's PNG (else only the statistics).
    pub write_frames: bool,
    /// View-ray traversal.
    pub traversal: Traversal,
    /// Shadow samples per hit (0: no shadows).
    pub shadow_steps: u32,
    /// Tile refinement: the screen-space error rule, and the deepest level
    /// for both modes.
    pub lod: LodRule,
    /// How tiles are chosen.
    pub mode: LodMode,
    /// Geomorph between tile levels (budget mode): a morphing tile is
    /// prepared and uploaded once per morph, and blended on the GPU.
    pub geomorph: bool,
    /// Halo requested with every tile, samples.
    pub halo: usize,
    /// The canopy fade: reference height (m), then low and high (px).
    pub fade: (f64, f64, f64),
    /// Tiles fetched at once, at most.
    pub in_flight: usize,
    /// Trees near the camera as splats (none: the ray-cast canopy only).
    pub trees: Option<TreeSettings>,
    /// Hull quads this many times the tiles' 16 samples
    /// ([`Renderer::with_hull_factor`](crate::client::render::Renderer::with_hull_factor); 4 suits software rasterisers).
    pub hull_factor: usize,
    /// Where rays are cast ([`Renderer::with_ray_pass`](crate::client::render::Renderer::with_ray_pass)).
    pub ray_pass: RayPass,
    /// Each frame is rendered again for this long and its median time
    /// reported and fed to the cost model (0: once): see `held`.
    pub hold_ms: f64,
}

impl Default for FlyOptions {
    fn default() -> Self {
        FlyOptions {
            frames: 60,
            size: (640, 480),
            out_dir: None,
            overwrite: false,
            watch_signals: false,
            write_frames: true,
            traversal: Traversal::Exact,
            shadow_steps: 10,
            lod: LodRule { max_error_px: 2.0, max_level: 13 },
            mode: LodMode::Sse,
            geomorph: false,
            halo: 32,
            fade: (30.0, 0.5, 2.0),
            in_flight: 8,
            trees: Some(TreeSettings::default()),
            hull_factor: 1,
            ray_pass: RayPass::Fragment,
            hold_ms: 0.0,
        }
    }
}

/// Most steps of the linear march (a ray of more would stall the frame).
pub const MAX_LINEAR_STEPS: u32 = 4096;

/// Parses `exact` or `linear:STEPS` (1 to [`MAX_LINEAR_STEPS`]).
pub fn parse_traversal(text: &str) -> Option<Traversal> {
    match text.split_once(':') {
        None if text.eq_ignore_ascii_case("exact") => Some(Traversal::Exact),
        Some((kind, steps)) if kind.eq_ignore_ascii_case("linear") => {
            steps.parse().ok().filter(|s| (1..=MAX_LINEAR_STEPS).contains(s)).map(Traversal::Linear)
        }
        _ => None,
    }
}
