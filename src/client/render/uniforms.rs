//! The GPU's uniform blocks: the Rust twins of `Frame` and `Tile` in
//! `shaders/common.wgsl`, field for field (a test checks the layout against
//! naga's), and how they are filled from a camera, a tile and the settings.

use super::super::camera::Camera;
use super::super::raycast::{self, Fade, Traversal};
use super::super::tile::TileData;
use glam::DVec3;

/// Levels the mipmap atlas can describe.
pub const MAX_MIP_LEVELS: usize = 16;
/// Stride of per-tile uniforms in their buffer (the dynamic-offset alignment).
pub const TILE_STRIDE: u64 = 256;

/// Per frame.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FrameUniform {
    /// Projection.
    pub proj: [[f32; 4]; 4],
    /// Sky colour, ambient light.
    pub sky: [f32; 4],
    /// Canopy reference height, fade low and high (px), focal length (px).
    pub fade: [f32; 4],
    /// Width, height, near plane, focal length (px).
    pub viewport: [f32; 4],
    /// Shadow weight, softness, unused, unused.
    pub shadow: [f32; 4],
    /// Canopy tint.
    pub canopy_tint: [f32; 4],
    /// Tree range, blend band and distance between the knots of
    /// `tree_drawn` (m), unused.
    pub trees: [f32; 4],
    /// Share of trees drawn at each knot ([`raycast::TreeBlend::drawn`]).
    pub tree_drawn: [[f32; 4]; raycast::DRAWN_KNOTS / 4],
    /// Unused (the traversal is the pipeline's `LINEAR`), linear steps,
    /// unused, sun on.
    pub mode: [u32; 4],
    /// Mipmap atlas rectangles per level.
    pub mip_rects: [[u32; 4]; MAX_MIP_LEVELS],
}

/// Per tile, padded to [`TILE_STRIDE`].
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TileUniform {
    /// Tile-local metres → camera space.
    pub model_view: [[f32; 4]; 4],
    /// Camera in the tile frame; hull fade reach.
    pub camera: [f32; 4],
    /// Sun direction in the tile frame; shadow reach in samples.
    pub sun: [f32; 4],
    /// Spacing east and north, centre index, samples per side.
    pub grid: [f32; 4],
    /// Lowest ground, highest CEM, hull bottom, terrain mesh drop.
    pub range: [f32; 4],
    /// Halo, texels per side, slot, top mipmap level.
    pub index: [i32; 4],
    /// Draw mode, draw index + 1, shadow steps, morph layer + 1 (0: none).
    pub flags: [u32; 4],
    /// Highest CEM over all texels (the halo too); how far from the
    /// tile's edge the crack filler is drawn, samples (`f32::MAX` when drawn plain).
    pub texels: [f32; 4],
    /// Morph weight of the tile's own heights (against the coarser
    /// surface in its morph layer), unused × 3.
    pub morph: [f32; 4],
    /// First of the tile's splats in the frame's instance buffer, their
    /// count, unused × 2.
    pub splats: [u32; 4],
    /// Pixels its box covers on screen: x0, y0, x1, y1 (x1, y1 excluded).
    pub screen: [u32; 4],
    /// Nearest distance from the camera to its box (m), unused × 3.
    pub near: [f32; 4],
    _pad: [f32; 4],
}

/// Where and how a tile is drawn.
#[derive(Clone, Debug)]
pub struct Placement {
    /// Its place among the frame's draws.
    pub draw: u32,
    /// Its texture slot.
    pub slot: u32,
    /// Its draw mode.
    pub mode: DrawMode,
    /// Side of the largest quad of its hull as uploaded, samples.
    pub hull_quad_samples: f32,
    /// Its morph layer and the weight of its own heights, if it morphs.
    pub morph: Option<(u32, f32)>,
    /// Its splats in the frame's instance buffer.
    pub splats: std::ops::Range<u32>,
    /// The nearest distance from the camera to its box ([`tile_near_m`]).
    pub near_m: f64,
}

/// How a tile is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DrawMode {
    /// Rays start on the hull's front faces.
    Hull = 0,
    /// The camera is inside the hull: back faces, rays from the camera.
    Inside = 1,
    /// No ray casting: the terrain mesh, texture mapped.
    Plain = 2,
}

/// What a frame is drawn with.
#[derive(Clone, Copy, Debug)]
pub struct FrameSettings {
    /// View-ray traversal.
    pub traversal: Traversal,
    /// Shadow samples per hit, for tiles drawn without a quality of their own.
    pub shadow_steps: u32,
    /// Unit direction to the sun (ECEF), or none.
    pub sun_ecef: Option<DVec3>,
    /// Canopy fade.
    pub fade: Fade,
}

impl FrameUniform {
    /// The frame block for `camera` and `settings`, with the atlas layout.
    pub fn new(camera: &Camera, settings: &FrameSettings, mip_rects: &[[u32; 4]]) -> FrameUniform {
        let mut rects = [[0u32; 4]; MAX_MIP_LEVELS];
        for (r, m) in rects.iter_mut().zip(mip_rects) {
            *r = *m;
        }
        let steps = match settings.traversal {
            Traversal::Exact => 0,
            Traversal::Linear(n) => n,
        };
        let f = &settings.fade;
        let rgb = |c: [f64; 3], a: f64| [c[0] as f32, c[1] as f32, c[2] as f32, a as f32];
        FrameUniform {
            proj: camera.projection().to_cols_array_2d(),
            sky: rgb(raycast::SKY, raycast::AMBIENT),
            fade: [f.canopy_ref_m as f32, f.lo_px as f32, f.hi_px as f32, f.focal_px as f32],
            viewport: [camera.width_px as f32, camera.height_px as f32, camera.near_m as f32, camera.focal_px() as f32],
            shadow: [raycast::SHADOW_WEIGHT as f32, raycast::SHADOW_SOFT_M as f32, 0.0, 0.0],
            canopy_tint: rgb(raycast::CANOPY_TINT, 1.0),
            trees: [f.trees.range_m as f32, f.trees.band_m as f32, f.trees.knot_m() as f32, 0.0],
            tree_drawn: std::array::from_fn(|k| std::array::from_fn(|i| f.trees.drawn[4 * k + i] as f32)),
            mode: [0, steps, 0, settings.sun_ecef.is_some() as u32],
            mip_rects: rects,
        }
    }
}

impl TileUniform {
    /// The tile block for `tile` placed by `at`, with `shadow_steps`
    /// shadow samples per hit.
    pub fn new(
        camera: &Camera,
        settings: &FrameSettings,
        tile: &TileData,
        at: Placement,
        shadow_steps: u32,
    ) -> TileUniform {
        let Placement { draw, slot, mode, hull_quad_samples, morph, splats, near_m } = at;
        let frame = &tile.frame;
        let to_local = frame.basis.transpose();
        let cam = frame.to_local(camera.position_ecef);
        let sun = settings.sun_ecef.map_or(DVec3::Z, |s| to_local * s);
        let hull = &tile.hull;
        // A hull vertex bounds samples up to a quad diagonal away and the
        // tile's height range apart.
        let quad = f64::from(hull_quad_samples) * tile.frame.spacing_m.max_element();
        let rise = (tile.range.max_m - tile.range.min_m) as f64;
        let reach = (quad * quad * 2.0 + rise * rise).sqrt();
        TileUniform {
            model_view: camera.model_view(frame).to_cols_array_2d(),
            camera: [cam.x as f32, cam.y as f32, cam.z as f32, reach as f32],
            sun: [sun.x as f32, sun.y as f32, sun.z as f32, tile.halo as f32],
            grid: [
                frame.spacing_m.x as f32,
                frame.spacing_m.y as f32,
                frame.centre_index() as f32,
                frame.samples as f32,
            ],
            range: [
                tile.range.min_m,
                tile.range.max_m,
                hull.bottom_m,
                if mode == DrawMode::Plain { 0.0 } else { filler_drop_m(tile) },
            ],
            index: [tile.halo as i32, tile.size as i32, slot as i32, tile.mip.levels() as i32 - 1],
            flags: [mode as u32, draw + 1, shadow_steps, morph.map_or(0, |(layer, _)| layer + 1)],
            texels: [
                tile.range.texels_max_m,
                if mode == DrawMode::Plain { f32::MAX } else { filler_band_samples(tile, cam) },
                0.0,
                0.0,
            ],
            morph: [morph.map_or(1.0, |(_, weight)| weight), 0.0, 0.0, 0.0],
            splats: [splats.start, splats.len() as u32, 0, 0],
            screen: screen_rect(camera, tile),
            near: [near_m as f32, 0.0, 0.0, 0.0],
            _pad: [0.0; 4],
        }
    }
}

/// How far the terrain mesh is lowered under a ray-cast tile, so that it
/// only shows through cracks between flat frames: its own error plus the
/// flat frame's misplacement, which on slopes up to 3:1 moves heights by
/// three times as much.
fn filler_drop_m(tile: &TileData) -> f32 {
    (tile.range.mesh_error_m as f64 + 3.0 * tile.flat_error_m() + 0.01 * tile.frame.spacing_m.min_element()) as f32
}

/// How far from the tile's edge the crack filler is drawn, samples, for a
/// camera at `cam` in the tile frame. A crack lies within the flat frame's
/// error of the true edge; a ray through it goes on under the surface
/// beside it and meets the filler, lowered by [`filler_drop_m`], within
/// `drop / tan θ` beyond it, θ the shallowest angle below the horizon at
/// which the camera sees the tile's top (the frame's, less the tilt of the
/// local vertical); then one cell of the box's overlap and one for safety.
/// Further in, the ray-cast surface hides the filler everywhere but
/// through nodata holes, where it would stand in for ground there is none
/// of. A camera not above the tile's top needs it everywhere.
fn filler_band_samples(tile: &TileData, cam: DVec3) -> f32 {
    let top = bounds(tile)[1].z;
    let far = corners(tile).iter().map(|c| (c.truncate() - cam.truncate()).length()).fold(0.0, f64::max);
    let theta = ((cam.z - top) / far).atan() - tile.frame.max_tilt_rad();
    if theta.is_nan() || theta <= 0.0 {
        return f32::MAX;
    }
    let band_m = tile.flat_error_m() + f64::from(filler_drop_m(tile)) / theta.tan();
    (band_m / tile.frame.spacing_m.min_element() + 2.0).min(f64::from(f32::MAX)) as f32
}

/// Whether a ray-cast tile needs its terrain mesh beneath it to fill cracks
/// (`terrain.rs`). Its box reaches a cell beyond its edge samples, so it
/// holds the tile's true footprint wherever the flat frame misplaces the
/// tile by less than a cell; with every tile's footprint inside its own box,
/// a ray cannot pass between tiles without meeting a surface. Half a cell
/// is taken, for safety: coarse tiles (levels 7 and 8 over rmnp and the
/// demo), high latitudes and the poles need the mesh, fine tiles do not
/// (a quarter of a cell at levels 9 to 13 there).
pub fn needs_filler(tile: &TileData) -> bool {
    tile.flat_error_m() >= 0.5 * tile.frame.spacing_m.min_element()
}

/// The pixels the tile's box covers on screen, `[x0, y0, x1, y1]` with
/// `x1, y1` excluded: the bounding rectangle of its corners' projections,
/// or the whole screen when a corner is not in front of the near plane.
pub fn screen_rect(camera: &Camera, tile: &TileData) -> [u32; 4] {
    let (w, h) = (camera.width_px, camera.height_px);
    let to_camera = camera.rotation.transpose();
    let f = camera.focal_px();
    let (mut lo, mut hi) = (glam::DVec2::splat(f64::INFINITY), glam::DVec2::splat(f64::NEG_INFINITY));
    for corner in corners(tile) {
        let v = to_camera * (tile.frame.to_ecef(corner) - camera.position_ecef);
        if -v.z <= camera.near_m {
            return [0, 0, w, h];
        }
        let px = glam::DVec2::new(0.5 * w as f64 + f * v.x / -v.z, 0.5 * h as f64 - f * v.y / -v.z);
        (lo, hi) = (lo.min(px), hi.max(px));
    }
    let clamp = |x: f64, max: u32| x.clamp(0.0, max as f64) as u32;
    [clamp(lo.x.floor(), w), clamp(lo.y.floor(), h), clamp(hi.x.ceil() + 1.0, w), clamp(hi.y.ceil() + 1.0, h)]
}

/// Whether every sample of the tile is close enough for the whole canopy
/// and far enough from the trees' splats ([`Fade::whole`]).
pub fn canopy_whole(camera: &Camera, tile: &TileData, fade: &Fade) -> bool {
    fade.whole(tile_near_m(camera, tile), tile_far_m(camera, tile))
}

/// The farthest distance from the camera to the tile's box.
pub fn tile_far_m(camera: &Camera, tile: &TileData) -> f64 {
    let cam = tile.frame.to_local(camera.position_ecef);
    corners(tile).iter().map(|c| (*c - cam).length()).fold(0.0, f64::max)
}

/// The nearest distance from the camera to the tile's box.
pub fn tile_near_m(camera: &Camera, tile: &TileData) -> f64 {
    let cam = tile.frame.to_local(camera.position_ecef);
    let [lo, hi] = bounds(tile);
    (cam.clamp(lo, hi) - cam).length()
}

/// Whether the camera is inside the tile's hull box.
pub fn camera_inside(camera: &Camera, tile: &TileData) -> bool {
    let cam = tile.frame.to_local(camera.position_ecef);
    let [lo, hi] = bounds(tile);
    cam.cmpge(lo).all() && cam.cmple(hi).all()
}

/// The local box of the cast range.
fn bounds(tile: &TileData) -> [DVec3; 2] {
    let n = tile.frame.samples as f64;
    let lo = tile.frame.local_xy(-1.0, -1.0).extend(tile.hull.bottom_m as f64);
    let hi = tile.frame.local_xy(n, n).extend(tile.range.max_m as f64);
    [lo, hi]
}

fn corners(tile: &TileData) -> [DVec3; 8] {
    let [lo, hi] = bounds(tile);
    std::array::from_fn(|k| DVec3::new([lo.x, hi.x][k & 1], [lo.y, hi.y][(k >> 1) & 1], [lo.z, hi.z][k >> 2]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{offset_of, size_of};

    /// Member offsets of a WGSL struct, by name, from naga's layout.
    fn wgsl_offsets(name: &str) -> (Vec<(String, u32)>, u32) {
        wgsl_offsets_in(&super::super::shaders::raycast_source(false, false), name)
    }

    fn wgsl_offsets_in(source: &str, name: &str) -> (Vec<(String, u32)>, u32) {
        let module = naga::front::wgsl::parse_str(source).expect("WGSL parses");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let (handle, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).expect("struct");
        let naga::TypeInner::Struct { members, .. } = &ty.inner else { panic!("{name} is not a struct") };
        (members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset)).collect(), layouter[handle].size)
    }

    #[test]
    fn uniform_blocks_match_their_wgsl_twins() {
        let frame = [
            ("proj", offset_of!(FrameUniform, proj)),
            ("sky", offset_of!(FrameUniform, sky)),
            ("fade", offset_of!(FrameUniform, fade)),
            ("viewport", offset_of!(FrameUniform, viewport)),
            ("shadow", offset_of!(FrameUniform, shadow)),
            ("canopy_tint", offset_of!(FrameUniform, canopy_tint)),
            ("trees", offset_of!(FrameUniform, trees)),
            ("tree_drawn", offset_of!(FrameUniform, tree_drawn)),
            ("mode", offset_of!(FrameUniform, mode)),
            ("mip_rects", offset_of!(FrameUniform, mip_rects)),
        ];
        let tile = [
            ("model_view", offset_of!(TileUniform, model_view)),
            ("camera", offset_of!(TileUniform, camera)),
            ("sun", offset_of!(TileUniform, sun)),
            ("grid", offset_of!(TileUniform, grid)),
            ("range", offset_of!(TileUniform, range)),
            ("index", offset_of!(TileUniform, index)),
            ("flags", offset_of!(TileUniform, flags)),
            ("texels", offset_of!(TileUniform, texels)),
            ("morph", offset_of!(TileUniform, morph)),
            ("splats", offset_of!(TileUniform, splats)),
            ("screen", offset_of!(TileUniform, screen)),
            ("near", offset_of!(TileUniform, near)),
        ];
        for (name, rust) in [("Frame", &frame[..]), ("Tile", &tile[..])] {
            let (wgsl, size) = wgsl_offsets(name);
            let rust: Vec<(String, u32)> = rust.iter().map(|(n, o)| (n.to_string(), *o as u32)).collect();
            assert_eq!(wgsl, rust, "{name}: fields and offsets");
            let rust_size = if name == "Frame" { size_of::<FrameUniform>() } else { offset_of!(TileUniform, _pad) };
            assert_eq!(size as usize, rust_size, "{name}: size");
        }
        assert_eq!(size_of::<TileUniform>() as u64, TILE_STRIDE);
        // The compute pass reads the same buffer as an array of blocks.
        let (_, slot) = wgsl_offsets_in(&super::super::shaders::compute_source(false), "TileSlot");
        assert_eq!(u64::from(slot), TILE_STRIDE);
    }
}
