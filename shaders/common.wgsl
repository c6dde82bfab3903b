// Shared declarations of the ray-casting shaders: the uniform blocks (their
// Rust twins are in src/client/render/uniforms.rs, checked field by field
// against naga's layout in a test), the bindings, and the tile texel access.
//
// Coordinates: sample space (i, j) east/north of the tile's south-west
// sample, heights and ray parameters in the tile's local metres
// (src/client/frame.rs). Texel (i + B, j + B) of the tile's slot holds sample
// (i, j); the cast range is samples -1 ..= N, cast cell m has its south-west
// corner at sample m - 1.

struct Frame {
    proj: mat4x4<f32>,
    // rgb: sky colour, a: ambient light.
    sky: vec4<f32>,
    // canopy reference height (m), fade low (px), fade high (px), focal length (px).
    fade: vec4<f32>,
    // width, height (px), near plane (m), focal length (px).
    viewport: vec4<f32>,
    // shadow weight, shadow softness (m), unused, unused.
    shadow: vec4<f32>,
    // rgb: canopy tint.
    canopy_tint: vec4<f32>,
    // Trees as splats (splat.wgsl): range (m; 0 without trees), blend band
    // (m), distance between the knots of tree_drawn (m), unused.
    trees: vec4<f32>,
    // Share of the trees drawn at knot k's distance k * trees.z, linear
    // between (raycast::TreeBlend::drawn): knot k is tree_drawn[k / 4][k % 4].
    tree_drawn: array<vec4<f32>, 4>,
    // unused (the traversal is the pipeline's LINEAR), linear steps,
    // unused, sun on.
    mode: vec4<u32>,
    // The maximum mipmap's levels in the atlas: x, y, width, height.
    mip_rects: array<vec4<u32>, 16>,
};

struct Tile {
    // Tile-local metres to camera space.
    model_view: mat4x4<f32>,
    // xyz: camera in the tile frame (m); w: hull fade reach (m).
    camera: vec4<f32>,
    // xyz: unit direction to the sun in the tile frame; w: shadow reach (samples).
    sun: vec4<f32>,
    // metres per sample east, north; centre index c; samples per side N.
    grid: vec4<f32>,
    // lowest ground, highest CEM, hull bottom (local m), how far the terrain
    // mesh is lowered (0 for tiles drawn plain, more under ray-cast ones).
    range: vec4<f32>,
    // halo B, texels per side, texture slot, top mipmap level.
    index: vec4<i32>,
    // draw mode (0 hull, 1 camera inside the hull, 2 plain), the tile's
    // place among the frame's draws + 1, shadow steps (the tile's ray-casting quality), morph layer + 1 (0: the
    // tile does not morph).
    flags: vec4<u32>,
    // highest CEM over all texels, halo included (local m); how far from
    // the tile's edge the crack filler is drawn (samples; the largest float when
    // the mesh is drawn plain); unused x2.
    texels: vec4<f32>,
    // weight of the tile's own heights against its morph layer's, unused x3.
    morph: vec4<f32>,
    // the tile's splats in the frame's instance buffer: first, count;
    // unused x2.
    splats: vec4<u32>,
    // The pixels its box covers on screen, x0, y0, x1, y1 (x1, y1
    // excluded): the compute passes' invocations (compute.wgsl).
    screen: vec4<u32>,
    // The nearest distance from the camera to its box (m; the order of
    // the frame's draws), unused x3.
    near: vec4<f32>,
};

const MODE_HULL: u32 = 0u;
const MODE_INSIDE: u32 = 1u;
const MODE_PLAIN: u32 = 2u;
const NODATA_BELOW: f32 = -1.0e29;
const NO_HIT: f32 = -1.0;

@group(0) @binding(0) var<uniform> frame: Frame;
// cem, ground, 4-sample zone, 32-sample zone.
@group(0) @binding(1) var texels: texture_2d_array<f32>;
// sRGB map colour; alpha holds the surface class.
@group(0) @binding(2) var colours: texture_2d_array<f32>;
// Maximum mipmap levels 1 and up packed in an atlas (frame.mip_rects).
@group(0) @binding(3) var mip: texture_2d_array<f32>;
@group(0) @binding(4) var gather_sampler: sampler;
// Morphing tiles' coarser surfaces: CEM, ground per texel (tile.flags.w).
@group(0) @binding(5) var morph_from: texture_2d_array<f32>;

// What the ray-casting pipeline is specialised for (render/pipeline.rs,
// RayVariant): morphing tiles (the blend is compiled only into theirs), and
// tiles whose whole canopy is drawn unfaded (no ground or fade is read).
override MORPHING: bool = false;
override CANOPY_WHOLE: bool = false;
// Rays march linearly (frame.mode.y steps) instead of traversing the mipmap.
override LINEAR: bool = false;
// `tile`, the tile being drawn, is declared by the entry points' part:
// a uniform at a dynamic offset for the fragments (tile_uniform.wgsl), one
// of an array for the compute passes (compute.wgsl).

// Texture accesses of this invocation: view ray (with the two gathers of the
// hit cell's shading), and shadow ray — the benchmark's "fetches per pixel".
var<private> view_fetches: u32 = 0u;
var<private> shadow_fetches: u32 = 0u;
// Leaf cells the exact traversal visited, their corners read or memoised
// (a leaf's patch test costs more than a step over the maximum mipmap).
var<private> leaf_cells: u32 = 0u;
// The last cell whose corners were read, and its faded corner heights: the
// hit cell is shaded from it, and consecutive samples in one cell share it.
var<private> memo_cell: vec2<i32> = vec2<i32>(-2147483647);
var<private> memo_heights: vec4<f32>;

fn texel(i: i32, j: i32) -> vec4<f32> {
    let b = tile.index.x;
    return textureLoad(texels, vec2<i32>(i + b, j + b), tile.index.z, 0);
}

// The layer of the morphing tile's coarser surface.
fn morph_layer() -> i32 {
    return i32(tile.flags.w) - 1;
}

// Bound of the surface over mipmap texel `cell` of `level`.
fn mip_bound(level: i32, cell: vec2<i32>) -> f32 {
    let r = frame.mip_rects[level];
    return textureLoad(mip, vec2<i32>(r.xy) + cell, tile.index.z, 0).r;
}

// Cells per side of `level`: the N + 1 cast cells halved, rounding up, per
// level (as MaxMipmap builds them; level 0 has no rectangle in the atlas).
fn mip_cells(level: i32) -> vec2<i32> {
    let cells = i32(tile.grid.w) + 1;
    return vec2<i32>((cells + (1 << u32(level)) - 1) >> u32(level));
}

