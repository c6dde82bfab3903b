//! Level-of-detail selection under a frame budget (issue 7): which tile
//! levels to draw, how many splats each tree group gets, how tiles morph
//! between levels, and how the per-frame work stays small.
//!
//! Pure math over plain data: no I/O, no threads, no tokio, no wgpu. The
//! client owns the GPU, the tile cache and the selection thread and feeds
//! this module numbers; the papers are in `shared/seeds/` (000: mixed
//! discrete/continuous selection and variable splitting; 001: geomorphing,
//! asynchronous selection, path prediction, cost feedback; 004: the distance
//! deferral table; dissertation chapter 8: the refined models).
//!
//! # How the client uses it, per selection (every `τ`, on its own thread)
//!
//! 1. **Predict the view** ([`predict`]): feed every frame's camera
//!    [`predict::Pose`] to a [`predict::PathPredictor`]; for a selection
//!    started at `t`, sample poses in [`predict::target_interval`]`(t, τ, 3)`
//!    and build the [`predict::conservative`] cone from the current pose and
//!    the motion limits. Cull against the cone (not the current frustum).
//! 2. **Tiles** (the discrete hierarchy): build a `Vec<`[`optimizer::Node`]`>`
//!    from the quadtree — parents before children, `parent` as an index —
//!    over the tiles that could be drawn (down to where tiles are loaded).
//!    Each node's `benefit` is [`model::tile_benefit`]`(projected_px,
//!    samples_per_side, smooth)` averaged over the sampled poses with
//!    [`predict::blend`] (0 for culled tiles), its `cost_ms` the
//!    [`model::CostModel::marginal_ms`] of its features (one tile, its
//!    ray-casting pixel·steps), the largest over the poses. Then
//!    [`optimizer::Forest::new`].
//! 3. **Trees** (the continuous variables): build once an
//!    [`split::ObjectTree`] over the [`splats::TreeField`]'s groups
//!    ([`splats::TreeField::item`]); per selection, [`split::split`] it with
//!    a closure giving a node's full-resolution benefit
//!    ([`model::group_weight`] of its projected size, `None` if culled or
//!    smaller than a pixel). Each [`split::Variable`] is an
//!    [`optimizer::Continuous`]: `weight`, `capacity` (splats),
//!    `cost_per_unit_ms` (the model's ms per splat).
//! 4. **Optimise**: [`optimizer::optimize`]`(&forest, &continuous,
//!    &Settings { budget_ms, deadline, .. })` returns a [`optimizer::Selection`]:
//!    `split[i]` per node ([`optimizer::Selection::drawn`] lists the tiles to
//!    draw), `resolutions[k]` per variable (splats for all groups below that
//!    node, shared in proportion to their capacity; per tree with
//!    [`splats::distribute`]), the predicted `cost_ms`, `overrun_ms` when
//!    even the cheapest cut exceeds the budget (it, or a cut no dearer, is
//!    still drawn), `upper_bound` (no selection can beat it) and why it
//!    stopped.
//! 5. **Morph** ([`morph`]): keep a [`morph::MorphTrack`] per tile region;
//!    for the selection's target interval call `request(level, target_s)`;
//!    each frame draw mesh [`morph::mesh_and_weight`]`(track.level_at(now))`
//!    with vertices at [`morph::morphed_height`]; fade splats against the
//!    canopy with [`splats::canopy_blend`].
//! 6. **Calibrate** ([`calibrate`]): after each frame, give the frame's
//!    [`model::CostFeatures`] and measured GPU ms to a
//!    [`calibrate::CostCalibrator`]; use its [`model::CostModel`] next time.
//!
//! Between selections, [`deferral::ThresholdRefiner`] keeps the tile cut
//! for a screen-error threshold `μ` exact every frame while evaluating only
//! the tiles whose status could have changed since the eye moved (the
//! client's `--lod sse` flights select with it: `client::sse`);
//! [`quadtree::TileQuadtree`] is a ready hierarchy for it and for benchmarks.
//!
//! Units are in the names: `_m` metres, `_ms` milliseconds, `_px` pixels,
//! `_s` seconds, `_rad` radians. Nothing here panics or returns NaN on
//! finite input; odd input (NaN, negative budgets, zero costs) is treated
//! as documented on each function.

pub mod calibrate;
pub mod deferral;
pub mod model;
pub mod morph;
pub mod optimizer;
pub mod predict;
pub mod quadtree;
pub mod splats;
pub mod split;

/// `x > 0`, false for NaN (so `!positive(x)` also catches NaN).
pub(crate) fn positive(x: f64) -> bool {
    x > 0.0
}

/// `x ≥ 0`, false for NaN.
pub(crate) fn non_negative(x: f64) -> bool {
    x >= 0.0
}
